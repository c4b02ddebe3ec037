"""`adaptune metric kitti GT EST`: the KITTI devkit metric of two pose files."""

from __future__ import annotations

import json
from pathlib import Path

import click


@click.group()
def metric() -> None:
    """Trajectory error metrics."""


@metric.command()
@click.argument("gt_poses", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("est_poses", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True,
              help="Print JSON (t_err_pct, r_err_deg_per_m, segments, per_length).")
def kitti(gt_poses: Path, est_poses: Path, as_json: bool) -> None:
    """KITTI devkit error of EST_POSES against GT_POSES (KITTI pose files, camera frame).

    Segments of 100..800 m starting every 10 frames; the mean over all segments, as
    evaluate_odometry.cpp computes it.
    """
    from pipeline.evaluation.kitti import evaluate_kitti_files

    result = evaluate_kitti_files(gt_poses, est_poses)
    if as_json:
        click.echo(json.dumps(result, indent=1))
        return
    click.echo(f"t_err {result['t_err_pct']:.4f} %   r_err {result['r_err_deg_per_m']:.6f} deg/m "
               f"({result['r_err_deg_per_m'] * 100:.4f} deg/100 m)   "
               f"{result['segments']} segments, {result['frames']} frames")
