"""``adaptune study real-studies``: every unit's own study of one algorithm (real/dvc.yaml stage;
``studies.real.study``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, params_option
from stages.study.real import algorithm_option


@click.command("real-studies")
@params_option
@algorithm_option
@dir_option("--units", "units_dir", help="The units (real-units).")
@dir_option("--out", help="Folder of the units' own studies.")
def real_studies(params_path: Path, algorithm: str, units_dir: Path, out: Path) -> None:
    """Every unit's own study of the algorithm (resumable)."""
    from studies.real.settings import load_settings
    from studies.real.study import unit_studies

    results = unit_studies(units_dir, algorithm, out, load_settings(params_path))
    click.echo(f"{algorithm}: {len(results)} unit studies -> {out}", err=True)
