"""`adaptune export TRAJ --format kitti|tum --out FILE`: Parquet -> text for evo / devkit."""

from __future__ import annotations

import logging
from pathlib import Path

import click

log = logging.getLogger(__name__)


@click.command()
@click.argument("trajectory", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["kitti", "tum"]), required=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True)
def export(trajectory: Path, fmt: str, out: Path) -> None:
    """Write TRAJECTORY (T_world_lidar Parquet) as a KITTI or TUM text file."""
    from pipeline.evaluation.posefile import export_trajectory

    n = export_trajectory(trajectory, fmt, out)
    log.info("%s: %d poses as %s", out, n, fmt)
