"""`adaptune descriptors`: the environment descriptor of every frame, and its PCA."""

from __future__ import annotations

from pathlib import Path

import click

from pipeline.config import load_section
from stages.common import dir_option, file_option, params_option, sequences_option


@click.command()
@params_option
@sequences_option
@file_option("--out", help="descriptors Parquet (sequence, frame, stamp_ns, d0..d89).")
@file_option("--environment", help="environment Parquet (sequence, frame, e0..e9).")
@dir_option("--pca", "pca_dir",
            help="PCA folder (mean.npy, components.npy, scale.npy, pca.json).")
def descriptors(
    params_path: Path | None, sequence_dir: Path, out: Path, environment: Path, pca_dir: Path
) -> None:
    """Descriptor of every frame of every sequence; PCA fitted on the training frames."""
    from pipeline.descriptors.dataset import (
        DescriptorsSection,
        describe_dataset,
        write_descriptor_set,
    )

    section = load_section(params_path, "descriptors", DescriptorsSection)
    ds = describe_dataset(sequence_dir, section)
    write_descriptor_set(ds, out, environment, pca_dir)
    ratio = float(ds.pca.explained_variance_ratio.sum())
    click.echo(
        f"{len(ds.frames)} frames of {len(set(ds.sequences.tolist()))} sequences -> {out}; "
        f"PCA {ds.pca.dim} components explain {ratio:.1%} (training frames)",
        err=True,
    )
