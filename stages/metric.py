"""`adaptune metric kitti GT EST` (the KITTI devkit metric) and `adaptune metric rte GT EST
--length L` (RTE, APE, RPE of runs of any length)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from stages.common import FILE, echo_output
from stages.ingest import POSE_FORMATS


@click.group()
def metric() -> None:
    """Trajectory error metrics."""


@metric.command()
@click.argument("gt_poses", type=FILE)
@click.argument("est_poses", type=FILE)
@click.option("--json", "as_json", is_flag=True,
              help="Print JSON (t_err_pct, r_err_deg_per_m, segments, per_length).")
def kitti(gt_poses: Path, est_poses: Path, as_json: bool) -> None:
    """KITTI devkit error of EST_POSES against GT_POSES (KITTI pose files, camera frame).

    Segments of 100..800 m starting every 10 frames; the mean over all segments, as
    evaluate_odometry.cpp computes it.
    """
    from pipeline.metrics.kitti import evaluate_kitti_files

    result = evaluate_kitti_files(gt_poses, est_poses)
    if as_json:
        echo_output(json.dumps(result, indent=1))
        return
    echo_output(f"t_err {result['t_err_pct']:.4f} %   r_err {result['r_err_deg_per_m']:.6f} "
                f"deg/m ({result['r_err_deg_per_m'] * 100:.4f} deg/100 m)   "
                f"{result['segments']} segments, {result['frames']} frames")


@metric.command()
@click.argument("ground_truth", type=FILE)
@click.argument("estimate", type=FILE)
@click.option("--length", "length_m", type=float, required=True,
              help="L [m]: the sub-trajectory length of the RTE (any length; KITTI's 100-800 m "
              "are `metric kitti`).")
@click.option("--scale", is_flag=True, help="Align with scale too (Sim(3); monocular methods).")
@click.option("--gt-format", type=click.Choice(POSE_FORMATS), default="auto", show_default=True,
              help="Format of a GROUND_TRUTH pose file.")
@click.option("--est-format", type=click.Choice(POSE_FORMATS), default="auto",
              show_default=True, help="Format of an ESTIMATE pose file.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON (rte, ape, rpe).")
def rte(ground_truth: Path, estimate: Path, length_m: float, scale: bool, gt_format: str,
        est_format: str, as_json: bool) -> None:
    """RTE over --length L (the pipeline's per-start-frame error), evo-style APE (Umeyama
    alignment) and RPE (1 frame) of ESTIMATE against GROUND_TRUTH.

    Each is a sequence MCAP (its ground truth), a trajectory Parquet (`adaptune run`) or a pose
    file (KITTI, TUM, EuRoC CSV, 4x4 blocks). Stamped poses pair by time (10 ms), others by
    index.
    """
    from pipeline.metrics.trajectory_error import evaluate_files

    r = evaluate_files(ground_truth, estimate, length_m, scale, gt_format,  # type: ignore[arg-type]
                       est_format)  # type: ignore[arg-type]
    if as_json:
        echo_output(json.dumps(r, indent=1))
        return
    rt, ape, rpe = r["rte"], r["ape"], r["rpe"]
    stats = "rmse {rmse:.4f}  mean {mean:.4f}  median {median:.4f}  std {std:.4f}  " \
            "min {min:.4f}  max {max:.4f} m"
    echo_output("\n".join([
        f"{r['frames']} frames, {r['path_m']:.1f} m of ground truth",
        f"RTE  L = {rt['length_m']:g} m, {rt['segments']} start frames: "
        f"t_err {rt['t_err_pct']:.4f} %  r_err {rt['r_err_deg_per_m']:.6f} deg/m",
        f"APE  {ape['alignment']} Umeyama alignment (scale {ape['scale']:.4f}): "
        + stats.format(**ape),
        "RPE  1 frame: " + stats.format(**rpe)]))
