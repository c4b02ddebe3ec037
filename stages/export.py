"""`adaptune export TRAJ --format kitti|tum --out FILE`: Parquet -> text for evo / the devkit.

By default the estimate is anchored at the ground truth of its first frame (from the sequence
the trajectory names, or --sequence); ``--frame kitti-camera`` writes KITTI's camera-0 frame;
``--ground-truth`` exports the ground truth of a sequence MCAP instead
(``pipeline.export`` documents the frames).
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import FILE, file_option, out_option

FRAMES = ["lidar", "kitti-camera"]


@click.command()
@click.argument("source", type=FILE)
@click.option("--format", "fmt", type=click.Choice(["kitti", "tum"]), required=True)
@out_option(help="The pose text file to write")
@click.option("--ground-truth", is_flag=True,
              help="SOURCE is a sequence MCAP: export its ground truth.")
@file_option("--sequence", required=False,
             help="The sequence MCAP of the trajectory [default: the one it names].")
@click.option("--anchor", type=click.Choice(["ground-truth", "identity"]),
              default="ground-truth", show_default=True,
              help="Start at the first frame's ground-truth pose, or where the odometry did.")
@click.option("--frame", type=click.Choice(FRAMES), default="lidar", show_default=True,
              help="lidar: T_world_lidar; kitti-camera: KITTI's camera-0 poses (poses/NN.txt).")
@file_option("--calib", required=False,
             help="KITTI calib.txt for --frame kitti-camera [default: the sequence's].")
def export(source: Path, fmt: str, out: Path, ground_truth: bool, sequence: Path | None,
           anchor: str, frame: str, calib: Path | None) -> None:
    """Write SOURCE (a trajectory Parquet, or with --ground-truth a sequence MCAP) as a KITTI
    or TUM pose file."""
    from pipeline.export import export_ground_truth, export_trajectory

    if ground_truth:
        n = export_ground_truth(source, fmt, out, frame=frame, calib=calib)
        what = "ground truth"
    else:
        n = export_trajectory(source, fmt, out, sequence=sequence, anchor=anchor, frame=frame,
                              calib=calib)
        what = f"anchored at {anchor}" if anchor == "ground-truth" else "as estimated"
    click.echo(f"{out}: {n} poses as {fmt}, {frame} frame, {what}", err=True)
