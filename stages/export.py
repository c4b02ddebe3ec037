"""`adaptune export SOURCE --format kitti|tum|optuna --out FILE`: what adaptune wrote, for the
tools users already have.

- kitti, tum: a trajectory Parquet (or with ``--ground-truth`` a sequence MCAP) as pose text for
  evo and the KITTI devkit. By default the estimate is anchored at the ground truth of its first
  frame (from the sequence the trajectory names, or --sequence); ``--frame kitti-camera`` writes
  KITTI's camera-0 frame (``pipeline.export`` documents the frames).
- optuna: one or more trials output folders (``results/trials``, ``results/fixed``) as an
  Optuna SQLite storage for ``optuna-dashboard sqlite:///FILE``
  (``pipeline.tuning.optuna_export``); the lost trials left out are counted on stderr.
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import NoDashPath, file_option, out_option, refuse_dash

FRAMES = ["lidar", "kitti-camera"]
TRAJECTORY_OPTIONS = ("ground_truth", "sequence", "anchor", "frame", "calib")
"""Options of a trajectory export (kitti, tum) that --format optuna refuses."""


@click.command()
@click.argument("sources", nargs=-1, required=True,
                type=NoDashPath(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["kitti", "tum", "optuna"]), required=True,
              help="kitti, tum: pose text of one trajectory; optuna: an Optuna SQLite storage "
              "of the studies of one or more trials folders.")
@out_option(help="The file to write: pose text, or with --format optuna the SQLite storage")
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
@click.pass_context
def export(ctx: click.Context, sources: tuple[Path, ...], fmt: str, out: Path,
           ground_truth: bool, sequence: Path | None, anchor: str, frame: str,
           calib: Path | None) -> None:
    """Write SOURCE (a trajectory Parquet, or with --ground-truth a sequence MCAP) as a KITTI
    or TUM pose file, or with --format optuna the trials folders SOURCE... (results/trials,
    results/fixed) as an Optuna storage for optuna-dashboard."""
    from pipeline.errors import ConfigError

    if fmt == "optuna":
        given = [f"--{o.replace('_', '-')}" for o in TRAJECTORY_OPTIONS
                 if ctx.get_parameter_source(o) != click.core.ParameterSource.DEFAULT]
        if given:
            raise ConfigError(f"--format optuna exports trials folders: {', '.join(given)} "
                              "belong to a trajectory export (kitti, tum)")
        if str(out) == "-":
            refuse_dash("--out of --format optuna (an SQLite file)")
        _export_optuna(sources, out)
        return
    if len(sources) != 1:
        raise ConfigError(f"--format {fmt} exports one trajectory, got {len(sources)} sources")
    _export_trajectory(sources[0], fmt, out, ground_truth, sequence, anchor, frame, calib)


def _export_trajectory(source: Path, fmt: str, out: Path, ground_truth: bool,
                       sequence: Path | None, anchor: str, frame: str,
                       calib: Path | None) -> None:
    from pipeline.errors import InputError
    from pipeline.export import export_ground_truth, export_trajectory

    if source.is_dir():
        raise InputError(f"{source}: a trajectory export reads a file (a trajectory Parquet or "
                         "a sequence MCAP); a trials folder exports with --format optuna")
    if ground_truth:
        n = export_ground_truth(source, fmt, out, frame=frame, calib=calib)
        what = "ground truth"
    else:
        n = export_trajectory(source, fmt, out, sequence=sequence, anchor=anchor, frame=frame,
                              calib=calib)
        what = f"anchored at {anchor}" if anchor == "ground-truth" else "as estimated"
    click.echo(f"{out}: {n} poses as {fmt}, {frame} frame, {what}", err=True)


def _export_optuna(folders: tuple[Path, ...], out: Path) -> None:
    from pipeline.tuning.optuna_export import export_optuna

    studies = export_optuna(folders, out)
    lost = sum(s.lost for s in studies)
    click.echo(f"{out}: {len(studies)} Optuna studies, {sum(s.trials for s in studies)} trials"
               f"{f', {lost} lost trials left out' if lost else ''}; "
               f"optuna-dashboard sqlite:///{out.resolve()}", err=True)
    for s in studies:
        states = ", ".join(f"{n} {state.lower()}" for state, n in sorted(s.states.items()))
        click.echo(f"  {s.name}: {states or 'no trials'}"
                   f"{f' ({s.lost} lost, left out)' if s.lost else ''}", err=True)
