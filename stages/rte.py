"""`adaptune rte`: score every trial into the DuckDB results database (dvc stage)."""

from __future__ import annotations

import logging
from pathlib import Path

import click

from stages.common import params_option

log = logging.getLogger(__name__)

_path = click.Path(path_type=Path)


@click.command()
@params_option
@click.option("--sequences", type=_path, required=True, help="Folder of sequence MCAPs.")
@click.option("--trials", "trials_dir", type=_path, help="Per-sequence SMBO output folder.")
@click.option("--fixed", "fixed_dir", type=_path, help="Joint SMBO output folder.")
@click.option("--descriptors", type=_path, help="data/descriptors.parquet.")
@click.option("--environment", type=_path, help="data/environment.parquet.")
@click.option("--db", type=_path, required=True, help="The database to (re)build.")
def rte(params_path: Path, sequences: Path, trials_dir: Path | None, fixed_dir: Path | None,
        descriptors: Path | None, environment: Path | None, db: Path) -> None:
    """Build the results database: sequences, trials, rte_frames, rte_kitti, descriptors."""
    from pipeline.config import load_section
    from pipeline.evaluation.store import RteSection, build_database

    settings = load_section(params_path, "rte", RteSection)
    studies = {name: path for name, path in (("trials", trials_dir), ("fixed", fixed_dir))
               if path is not None}
    summary = build_database(db, sequences, studies, settings, descriptors, environment)
    log.info("%s: %d sequences, %d trials, %d rte_frames rows, %d rte_kitti rows",
             db, summary.sequences, summary.trials, summary.rte_frames, summary.rte_kitti)
