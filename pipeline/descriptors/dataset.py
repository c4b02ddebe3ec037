"""The descriptors of a data set (the ``descriptors`` stage): every frame of every sequence of
a sequences folder, the PCA fitted on the training frames, and their Parquet tables."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import ConfigDict, Field, model_validator

from pipeline.config import Section
from pipeline.descriptors import DEFAULT_DESCRIPTOR, Descriptor, make_descriptor
from pipeline.errors import ConfigError, InputError
from pipeline.pca import Pca, fit_pca


class DescriptorsSection(Section):
    """params.yaml ``descriptors``: the descriptor's ``type`` (``pipeline.descriptors``
    registry), its own settings beside it (for ``ndt_histogram``: voxel_size_m, min_points, t_e,
    range_bins, bin_m, normalize; pipeline/descriptors/ndt_histogram.py documents them), the
    PCA dimension and the worker processes."""

    model_config = ConfigDict(extra="allow", frozen=True)

    type: str = DEFAULT_DESCRIPTOR
    pca_dim: int = Field(10, ge=1)
    workers: int = Field(2, ge=1)

    @model_validator(mode="after")
    def _descriptor_settings(self) -> DescriptorsSection:
        try:
            width = self.descriptor().size
        except ConfigError as exc:
            raise ValueError(str(exc)) from None
        if self.pca_dim > width:
            raise ValueError(f"pca_dim must be <= the descriptor's width {width}, "
                             f"got {self.pca_dim}")
        return self

    def descriptor(self) -> Descriptor:
        """The descriptor these settings configure."""
        return make_descriptor(self.type, self.model_extra)


def describe_sequence(
    path: str | Path, descriptor: Descriptor
) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.float32]]:
    """Descriptor of every frame of one sequence MCAP: frames (N,), stamps_ns (N,), (N, F)."""
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        rows = [(scan.frame, scan.stamp_ns, descriptor.describe(scan.points_lidar))
                for scan in reader]
    if not rows:
        raise InputError(f"{path}: no frames")
    frames = np.array([r[0] for r in rows], np.int32)
    stamps = np.array([r[1] for r in rows], np.int64)
    return frames, stamps, np.stack([r[2] for r in rows]).astype(np.float32)


@dataclass
class DescriptorSet:
    """Descriptors of every frame of every sequence, and the PCA fitted on the training ones."""

    sequences: NDArray[np.str_]
    frames: NDArray[np.int32]
    stamps_ns: NDArray[np.int64]
    descriptors: NDArray[np.float32]
    pca: Pca

    @property
    def environment(self) -> NDArray[np.float32]:
        return self.pca.transform(self.descriptors).astype(np.float32)


def _describe_job(args: tuple[str, Descriptor]) -> tuple[NDArray[Any], ...]:
    return describe_sequence(args[0], args[1])


def describe_dataset(sequences_dir: str | Path, section: DescriptorsSection) -> DescriptorSet:
    """Descriptor of every frame of every sequence in index.json (a process pool of
    ``section.workers`` over the sequences) and the PCA fitted on the 'train' frames only."""
    from concurrent.futures import ProcessPoolExecutor

    from pipeline.sequence_index import read_index

    descriptor = section.descriptor()
    index = read_index(sequences_dir)
    train = index.names("train")
    for split in index.splits:
        if index.splits[split]:
            index.paths(split)  # every listed sequence exists
    names = index.all_names()
    jobs = [(str(Path(sequences_dir) / f"{n}.mcap"), descriptor) for n in names]
    if section.workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(min(section.workers, len(jobs))) as pool:
            results = list(pool.map(_describe_job, jobs))
    else:
        results = [_describe_job(j) for j in jobs]
    seqs = np.concatenate(
        [np.full(len(r[0]), n, dtype=object) for n, r in zip(names, results, strict=True)]
    )
    frames = np.concatenate([r[0] for r in results])
    stamps = np.concatenate([r[1] for r in results])
    desc = np.concatenate([r[2] for r in results])
    pca = fit_pca(desc[np.isin(seqs, train)], section.pca_dim, train)
    pca.descriptor = descriptor.to_json()
    return DescriptorSet(seqs.astype(str), frames, stamps, desc, pca)


def write_descriptor_set(
    ds: DescriptorSet, out: str | Path, environment: str | Path, pca_dir: str | Path
) -> None:
    """descriptors Parquet (``schemas.arrow.descriptors_schema`` of the descriptor's width),
    environment Parquet (``environment_schema``: sequence, frame, e0..) and the PCA folder,
    each written atomically."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.io_utils import atomic_path
    from schemas.arrow import descriptors_schema, environment_schema

    width = ds.descriptors.shape[1]
    if ds.pca.descriptor and ds.pca.descriptor.get("size", width) != width:
        raise ConfigError(f"the descriptor has {width} values, its settings say "
                          f"{ds.pca.descriptor['size']}")
    base = [pa.array(ds.sequences, pa.string()), pa.array(ds.frames, pa.int32())]
    cols = [*base, pa.array(ds.stamps_ns, pa.int64())]
    cols += [pa.array(ds.descriptors[:, i], pa.float32()) for i in range(width)]
    schema = descriptors_schema(width, json.dumps(ds.pca.descriptor, sort_keys=True))
    table = pa.Table.from_arrays(cols, schema=schema)
    env = ds.environment
    env_table = pa.Table.from_arrays(
        base + [pa.array(env[:, i], pa.float32()) for i in range(env.shape[1])],
        schema=environment_schema(env.shape[1]),
    )
    with atomic_path(out) as tmp:
        pq.write_table(table, tmp)
    with atomic_path(environment) as tmp:
        pq.write_table(env_table, tmp)
    ds.pca.save(pca_dir)
