"""``adaptune study real-folds``: every fold of the real-data study for one algorithm: the joint
study, the model, the in-sample best and the suite (real/dvc.yaml stage; ``studies.real.fold``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option
from stages.study.real import algorithm_option


@click.command("real-folds")
@params_option
@algorithm_option
@dir_option("--units", "units_dir", help="The units (real-units).")
@file_option("--descriptors", "descriptors_path", help="Every unit's descriptors (Parquet).")
@dir_option("--studies", "studies_dir", help="The units' own studies (real-studies).")
@dir_option("--out", help="Folder of the folds, one subfolder each.")
def real_folds(params_path: Path, algorithm: str, units_dir: Path, descriptors_path: Path,
               studies_dir: Path, out: Path) -> None:
    """Every fold of the algorithm: fixed, adaptive and the in-sample best on its test units."""
    from studies.real.settings import load_settings
    from studies.real.study import run_folds

    suites = run_folds(units_dir, descriptors_path, studies_dir, out,
                       load_settings(params_path), algorithm)
    click.echo(f"{algorithm}: {len(suites)} folds -> {out}", err=True)
