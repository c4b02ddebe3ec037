"""Helpers shared by the thin stage commands (click options, params loading)."""

from __future__ import annotations

from pathlib import Path

import click

params_option = click.option(
    "--params", "params_path", type=click.Path(dir_okay=False, path_type=Path),
    default=Path("params.yaml"), show_default=True, help="The params file (one section per stage).",
)
