"""``adaptune study real-models``: the real-data deploy models of one algorithm, one per sensor
(real/dvc.yaml stage; ``studies.real.study.deploy_models``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option
from stages.study.real import algorithm_option


@click.command("real-models")
@params_option
@algorithm_option
@dir_option("--units", "units_dir", help="The units (real-units).")
@file_option("--descriptors", "descriptors_path", help="Every unit's descriptors (Parquet).")
@dir_option("--studies", "studies_dir", help="The units' own studies (real-studies).")
@dir_option("--work", "work_dir", help="Folder for each sensor's database and PCA.")
@dir_option("--out", help="Folder of the models: <out>/<sensor>/<algorithm>.")
def real_models(params_path: Path, algorithm: str, units_dir: Path, descriptors_path: Path,
                studies_dir: Path, work_dir: Path, out: Path) -> None:
    """One deploy model per sensor, trained on all of that sensor's units."""
    from studies.real.settings import load_settings
    from studies.real.study import deploy_models

    models = deploy_models(units_dir, descriptors_path, studies_dir, work_dir, out,
                           load_settings(params_path), algorithm)
    for sensor, path in models.items():
        click.echo(f"{algorithm} on {sensor}: {path}", err=True)
