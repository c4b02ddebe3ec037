"""``adaptune study real-units``: every run of the real-data study cut into its two halves by
distance (real/dvc.yaml stage; ``studies.real.units``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, params_option


@click.command("real-units")
@params_option
@dir_option("--runs", "runs_dir", help="The ingested runs (the data section's sequences).")
@dir_option("--out", help="Folder for the units' MCAPs, index.json and units.json.")
def real_units(params_path: Path, runs_dir: Path, out: Path) -> None:
    """Cut every run of the study into its two halves by distance."""
    from studies.real.settings import load_settings
    from studies.real.units import make_units

    settings = load_settings(params_path)
    units = make_units(runs_dir, [r.name for r in settings.real.runs],
                       settings.trials.penalty_pct, out)
    click.echo(f"{len(units)} units of {len(settings.real.runs)} runs -> {out}", err=True)
