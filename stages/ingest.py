"""``adaptune ingest {kitti,rosbag,folder,mcap}``: convert recorded scans into a sequence MCAP;
``adaptune ingest-set``: the recordings of the params section ``data`` (the dvc stage)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from stages.common import (
    DIR,
    FILE,
    PATH,
    compose,
    dir_option,
    file_option,
    out_option,
    params_option,
)

mcap_out_option = out_option(help="The sequence MCAP to write (atomically)")
name_option = click.option("--name", default=None, help="Sequence name (default: from the input).")
poses_option = click.option(
    "--poses", type=PATH, default=None,
    help="Ground-truth pose file: KITTI (12 numbers a line, line k = scan k), TUM (stamp tx ty "
    "tz qx qy qz qw), EuRoC/ASL CSV with its header, or a 4x4 matrix a pose on 4 lines "
    "(element (3,3): 1 or the stamp [s]). Stamped poses are matched by time.",
)
POSE_FORMATS = ("auto", "kitti", "tum", "euroc", "matrix4")
"""pipeline.posefile.POSE_FORMATS (kept here so that --help imports no numpy)."""
format_option = click.option(
    "--poses-format", type=click.Choice(POSE_FORMATS),
    default="auto", show_default=True,
    help="Format of --poses (auto: from the content, where that is unambiguous).",
)
extrinsic_option = click.option(
    "--extrinsic", "--calib", "extrinsic", default=None,
    help="T_x_lidar, LiDAR -> the frame the poses describe (KITTI's Tr): 12 or 16 numbers "
    "(row-major), a file of them, or a KITTI calib.txt. The poses become inv(E) P E. Without "
    "it, poses that move along the sensor's z axis (a camera's) get a warning.",
)
source_options = compose(
    extrinsic_option,
    name_option,
    click.option("--sensor", default="unknown", show_default=True,
                 help="Sensor name recorded in the sequence (e.g. os1_64, hdl32, vlp16)."),
    click.option("--intensity", type=click.Choice(["auto", "keep"]), default="auto",
                 show_default=True,
                 help="auto: scale 0-255 or 0-65535 intensities to 0-1 (as KITTI's); keep: as "
                 "recorded. The sequence's metadata says which."),
)
"""The options every recorded source takes: extrinsic, name, sensor, intensity."""
recording_options = compose(
    mcap_out_option,
    click.option("--topic", default=None,
                 help="PointCloud2 topic (default: the only one there is)."),
    click.option("--gt-topic", default=None,
                 help="Ground-truth topic: PoseStamped, Odometry or TF (tf2_msgs/TFMessage) "
                 "[the only PoseStamped / Odometry topic, where there is exactly one]."),
    click.option("--gt-child-frame", default=None,
                 help="With a TF --gt-topic: the child frame whose pose is the ground truth."),
    poses_option,
    format_option,
)
"""The options of a recording (ROS bag, MCAP): topics, ground truth, poses."""


def _done(report: Any) -> None:
    truth = "no" if not report.has_ground_truth else (
        f"yes ({report.ground_truth_from})" if report.ground_truth_from else "yes")
    click.echo(
        f"{report.out}: {report.frames} frames, {report.points} points"
        f"{f' ({report.dropped_points} non-finite dropped)' if report.dropped_points else ''}, "
        f"ground truth: {truth}, {report.seconds:.1f} s",
        err=True,
    )


GT_KEYS = ("gt_topic", "gt_child_frame", "poses", "poses_format", "extrinsic")
"""The options that make a source's GroundTruthOptions (pipeline.sources.poses)."""


def _with_ground_truth(options: dict[str, Any]) -> dict[str, Any]:
    """``options`` with the GT_KEYS replaced by one checked ``gt`` (GroundTruthOptions)."""
    from pipeline.config import validate_section
    from pipeline.sources.poses import GroundTruthOptions

    given = {k: options.pop(k) for k in GT_KEYS if k in options}
    given = {k: str(v) for k, v in given.items() if v is not None}
    return {**options, "gt": validate_section(GroundTruthOptions, "ingest", given)}


@click.group()
def ingest() -> None:
    """Convert KITTI, ROS bags, MCAP recordings or scan folders into a sequence MCAP."""


@ingest.command("kitti")
@click.argument("root", type=DIR)
@click.argument("seq")
@mcap_out_option
@click.option("--start", type=int, default=None, help="First KITTI frame number (default 0).")
@click.option(
    "--end", type=int, default=None, help="Last KITTI frame number, INCLUSIVE (default: the last)."
)
@name_option
def kitti(
    root: Path, seq: str, out: Path, start: int | None, end: int | None, name: str | None
) -> None:
    """KITTI odometry sequence SEQ under ROOT (ROOT/sequences/SEQ, ROOT/poses/SEQ.txt).

    Ground truth, where ROOT/poses/SEQ.txt exists, becomes T_world_lidar = inv(Tr) P Tr.
    """
    from pipeline.sources import ingest_kitti

    _done(ingest_kitti(root, seq, out, start=start, end=end, name=name))


@ingest.command("rosbag")
@click.argument("bag", type=PATH)
@recording_options
@source_options
def rosbag(bag: Path, **options: Any) -> None:
    """ROS 1 .bag file or ROS 2 bag folder (sqlite3 or mcap storage)."""
    from pipeline.sources import ingest_rosbag

    _done(ingest_rosbag(bag, **_with_ground_truth(options)))


@ingest.command("folder")
@click.argument("folder", type=DIR)
@mcap_out_option
@poses_option
@format_option
@click.option("--times", type=PATH, default=None,
              help="Stamps file (seconds, one a line); default: file names that are stamps, "
              "else the pose file's stamps, else frame / --rate.")
@click.option("--rate", "rate_hz", type=float, default=10.0, show_default=True,
              help="Scan rate [Hz].")
@source_options
def folder(folder: Path, **options: Any) -> None:
    """Scan files (.bin / .pcd / .ply) of FOLDER, one a frame, in the order of the numbers in
    their names (full2 before full10); names that allow no one order are refused."""
    from pipeline.sources import ingest_folder

    _done(ingest_folder(folder, **_with_ground_truth(options)))


@ingest.command("mcap")
@click.argument("path", type=FILE)
@recording_options
@source_options
def mcap(path: Path, **options: Any) -> None:
    """Any MCAP with PointCloud2 messages (cdr or ros1 encoding), e.g. a ROS 2 recording."""
    from pipeline.sources import ingest_mcap

    _done(ingest_mcap(path, **_with_ground_truth(options)))


@click.command("ingest-set")
@params_option
@dir_option("--out", "out_dir",
            help="Folder for <name>.mcap and index.json (data/recordings).")
@file_option("--record", "record_path", required=False,
             help="Write what each source became here (records/ingest.json): its sequences, "
                  "their frames and path lengths, its RTE length, the pieces dropped.")
def ingest_set(params_path: Path | None, out_dir: Path, record_path: Path | None) -> None:
    """Ingest the recordings of the params section ``data`` (dvc stage); relative paths in it
    are relative to the params file's folder. A recording whose ground truth runs no longer
    than its RTE length (its own length_m, else base.length_m) is refused before any is
    written; with pieces, a piece that does not is dropped (one line here and in the record),
    and the recording is refused when none is left."""
    from pipeline.config import BaseSection, load_section
    from pipeline.sequence_index import read_index
    from pipeline.sources.dataset import DataSection, ingest_data_set

    section = load_section(params_path, "data", DataSection)
    length_m = load_section(params_path, "base", BaseSection).length_m
    base_dir = params_path.parent if params_path is not None else Path.cwd()
    done = ingest_data_set(section, out_dir, base_dir, length_m)
    for report in done.reports:
        _done(report)
    for line in done.dropped:
        click.echo(line, err=True)
    if record_path is not None:
        from pipeline.outputs import write_json

        write_json(record_path, done.record)
    splits = read_index(out_dir).splits
    click.echo(f"{out_dir / 'index.json'}: "
               f"{', '.join(f'{len(v)} {k}' for k, v in splits.items())} sequences", err=True)
