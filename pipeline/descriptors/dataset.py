"""The descriptors of a data set (the ``descriptors`` stage): every frame of every sequence of
a sequences folder, the PCA fitted on the training frames, and their Parquet tables."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.descriptor import DescriptorConfig, describe
from pipeline.errors import ConfigError, InputError
from pipeline.pca import Pca, fit_pca


class DescriptorsSection(Section):
    """params.yaml ``descriptors`` (pipeline/descriptor.py documents every choice)."""

    voxel_size_m: float = Field(1.0, gt=0)
    min_points: int = Field(5, ge=3)
    t_e: float = Field(0.1, gt=0, lt=1)
    range_bins: int = Field(10, ge=1, le=10)
    bin_m: float = Field(3.0, gt=0)
    normalize: bool = True
    pca_dim: int = Field(10, ge=1, le=90)
    workers: int = Field(2, ge=1)

    def descriptor(self) -> DescriptorConfig:
        """The descriptor these settings configure."""
        return DescriptorConfig(self.voxel_size_m, self.min_points, self.t_e, self.range_bins,
                                self.bin_m, self.normalize)


def describe_sequence(
    path: str | Path, config: DescriptorConfig
) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.float32]]:
    """Descriptor of every frame of one sequence MCAP: frames (N,), stamps_ns (N,), (N, F)."""
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        rows = [(scan.frame, scan.stamp_ns, describe(scan.points_lidar, config)) for scan in reader]
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


def _describe_job(args: tuple[str, DescriptorConfig]) -> tuple[NDArray[Any], ...]:
    return describe_sequence(args[0], args[1])


def describe_dataset(sequences_dir: str | Path, section: DescriptorsSection) -> DescriptorSet:
    """Descriptor of every frame of every sequence in index.json (a process pool of
    ``section.workers`` over the sequences) and the PCA fitted on the 'train' frames only."""
    from concurrent.futures import ProcessPoolExecutor

    from pipeline.sequence_index import read_index

    config = section.descriptor()
    index = read_index(sequences_dir)
    train = index.names("train")
    for split in index.splits:
        if index.splits[split]:
            index.paths(split)  # every listed sequence exists
    names = index.all_names()
    jobs = [(str(Path(sequences_dir) / f"{n}.mcap"), config) for n in names]
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
    pca.descriptor = config.to_json()
    return DescriptorSet(seqs.astype(str), frames, stamps, desc, pca)


def write_descriptor_set(
    ds: DescriptorSet, out: str | Path, environment: str | Path, pca_dir: str | Path
) -> None:
    """descriptors Parquet (schemas.arrow.DESCRIPTORS), environment Parquet (sequence, frame,
    e0..) and the PCA folder, each written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.io_utils import atomic_path
    from schemas.arrow import DESCRIPTORS

    if ds.descriptors.shape[1] != 90:
        raise ConfigError(
            f"the DESCRIPTORS table has 90 columns, the descriptor has "
            f"{ds.descriptors.shape[1]} (range_bins must be 10)"
        )
    base = [pa.array(ds.sequences, pa.string()), pa.array(ds.frames, pa.int32())]
    cols = [*base, pa.array(ds.stamps_ns, pa.int64())]
    cols += [pa.array(ds.descriptors[:, i], pa.float32()) for i in range(90)]
    table = pa.Table.from_arrays(cols, schema=DESCRIPTORS)
    env = ds.environment
    env_schema = pa.schema(
        [
            pa.field("sequence", pa.string(), nullable=False),
            pa.field("frame", pa.int32(), nullable=False),
        ]
        + [pa.field(f"e{i}", pa.float32(), nullable=False) for i in range(env.shape[1])],
        metadata={**(DESCRIPTORS.metadata or {}), b"adaptune.table": b"environment"},
    )
    env_table = pa.Table.from_arrays(
        base + [pa.array(env[:, i], pa.float32()) for i in range(env.shape[1])], schema=env_schema
    )
    with atomic_path(out) as tmp:
        pq.write_table(table, tmp)
    with atomic_path(environment) as tmp:
        pq.write_table(env_table, tmp)
    ds.pca.save(pca_dir)
