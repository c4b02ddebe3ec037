"""``adaptune init DIR``: a new project's params.yaml and dvc.yaml from a list of recordings."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import DIR, FILE


@click.command("init")
@click.argument("directory", type=DIR)
@click.option("--recording", "-r", "recordings", multiple=True, type=click.Path(path_type=Path),
              help="A recording: a ROS 1 .bag, a ROS 2 bag folder, an .mcap, a folder of "
              ".bin / .pcd / .ply scans, a KITTI ROOT/sequences/NN folder, or a KITTI ROOT "
              "(its sequences with ground truth) (repeatable).")
@click.option("--list", "list_file", type=FILE, default=None,
              help="A file of recordings, one a line: PATH [key=value ...] with the keys of a "
              "params.yaml data source (split=validation, topic=/points, gt_topic=/odom, "
              "poses=gt.txt, ...); relative paths from the file's folder.")
@click.option("--validation", multiple=True, type=click.Path(path_type=Path),
              help="A recording of the validation split (repeatable) [the last recording, "
              "when no recording has a split].")
@click.option("--test", multiple=True, type=click.Path(path_type=Path),
              help="A recording of the test split (repeatable), evaluated, never tuned on.")
@click.option("--length", "length_m", type=float, default=None,
              help="base.length_m, the RTE's length [m]: every recording's ground truth must "
              "run longer [the code's default: 25].")
@click.option("--force", is_flag=True, help="Overwrite DIR's params.yaml and dvc.yaml.")
def init(directory: Path, recordings: tuple[Path, ...], list_file: Path | None,
         validation: tuple[Path, ...], test: tuple[Path, ...], length_m: float | None,
         force: bool) -> None:
    """Write DIR/params.yaml and DIR/dvc.yaml for a project on your recordings.

    Each recording's kind, point-cloud topic and ground truth (an Odometry / PoseStamped topic,
    or a pose file beside a folder's scans) are found where unambiguous, and every recording is
    opened to check it. Then, in DIR (a git + DVC repository: `git init && dvc init`):
    `dvc repro` ingests the recordings, tunes, fits the model artifact (model/) and evaluates.
    """
    from pipeline.project import Recording, init_project, read_recording_list

    listed = [Recording(p) for p in recordings]
    if list_file is not None:
        listed += read_recording_list(list_file)
    project = init_project(directory, listed, validation, test, force, length_m)
    splits = ", ".join(f"{len(v)} {k}" for k, v in project.splits().items())
    click.echo(f"{project.params}: {len(project.recordings())} recordings ({splits}), "
               f"evaluated on {' and '.join(project.evaluate_splits)}", err=True)
    for source in project.recordings():
        found = ", ".join(f"{k} {source[k]}" for k in ("topic", "gt_topic", "poses")
                          if source.get(k))
        click.echo(f"  {source['split']:<10} {source['kind']:<6} {source['path']}"
                   f"{f' ({found})' if found else ''}", err=True)
    click.echo(f"{project.dvc_yaml}: the stages from the recordings to model/ and the "
               f"evaluation\nnext: cd {directory}; git init; dvc init (unless it is a git + DVC "
               "repository already); edit params.yaml (trials.iterations, base.length_m); "
               "dvc repro", err=True)
