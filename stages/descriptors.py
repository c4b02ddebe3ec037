"""`adaptune descriptors`: the environment descriptor of every frame, and its PCA."""

from __future__ import annotations

from pathlib import Path

import click
from pydantic import Field

from pipeline.config import Section, load_section
from stages.common import params_option


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


@click.command()
@params_option
@click.option(
    "--sequences",
    "sequences_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder with index.json.",
)
@click.option(
    "--out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="descriptors Parquet (sequence, frame, stamp_ns, d0..d89).",
)
@click.option(
    "--environment",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="environment Parquet (sequence, frame, e0..e9).",
)
@click.option(
    "--pca",
    "pca_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="PCA folder (mean.npy, components.npy, scale.npy, pca.json).",
)
def descriptors(
    params_path: Path, sequences_dir: Path, out: Path, environment: Path, pca_dir: Path
) -> None:
    """Descriptor of every frame of every sequence; PCA fitted on the training frames."""
    from pipeline.descriptor import DescriptorConfig
    from pipeline.surrogate import describe_dataset, write_descriptor_set

    p = load_section(params_path, "descriptors", DescriptorsSection)
    config = DescriptorConfig(
        p.voxel_size_m, p.min_points, p.t_e, p.range_bins, p.bin_m, p.normalize
    )
    ds = describe_dataset(sequences_dir, config, p.pca_dim, p.workers)
    write_descriptor_set(ds, out, environment, pca_dir)
    ratio = float(ds.pca.explained_variance_ratio.sum())
    click.echo(
        f"{len(ds.frames)} frames of {len(set(ds.sequences.tolist()))} sequences -> {out}; "
        f"PCA {ds.pca.dim} components explain {ratio:.1%} (training frames)",
        err=True,
    )
