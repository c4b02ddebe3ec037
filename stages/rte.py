"""`adaptune rte`: score every trial into the DuckDB results database (dvc stage)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option, sequences_option


@click.command()
@params_option
@sequences_option
@dir_option("--trials", "trials_dir", required=False, help="Per-sequence SMBO output folder.")
@dir_option("--fixed", "fixed_dir", required=False, help="Joint SMBO output folder.")
@dir_option("--portfolio", "portfolio_dir", required=False,
            help="The portfolio study's output folder (adaptune portfolio).")
@file_option("--descriptors", required=False, help="data/descriptors.parquet.")
@file_option("--environment", required=False, help="data/environment.parquet.")
@file_option("--db", help="The database to (re)build.")
def rte(params_path: Path | None, sequence_dir: Path, trials_dir: Path | None,
        fixed_dir: Path | None, portfolio_dir: Path | None, descriptors: Path | None,
        environment: Path | None, db: Path) -> None:
    """Build the results database: sequences, trials, rte_frames, rte_kitti, descriptors."""
    from pipeline.config import BaseSection, load_section
    from pipeline.database.store import build_database
    from pipeline.metrics.section import DevkitSection

    length_m = load_section(params_path, "base", BaseSection).length_m
    devkit = load_section(params_path, "devkit", DevkitSection)
    studies = {name: path for name, path in (("trials", trials_dir), ("fixed", fixed_dir),
                                                  ("portfolio", portfolio_dir))
               if path is not None}
    summary = build_database(db, sequence_dir, studies, length_m, devkit, descriptors,
                             environment)
    click.echo(f"{db}: {summary.sequences} sequences, {summary.trials} trials, "
               f"{summary.rte_frames} rte_frames rows, {summary.rte_kitti} rte_kitti rows",
               err=True)
