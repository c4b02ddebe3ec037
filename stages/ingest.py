"""``adaptune ingest {kitti,rosbag,folder,mcap}``: convert recorded scans into a sequence MCAP."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from stages.common import params_option

if TYPE_CHECKING:
    from pipeline.sources.poses import PoseFormat

out_option = click.option(
    "--out",
    "out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="The sequence MCAP to write (atomically).",
)
name_option = click.option("--name", default=None, help="Sequence name (default: from the input).")
poses_option = click.option(
    "--poses",
    type=click.Path(path_type=Path),
    default=None,
    help="Ground-truth pose file: KITTI (12 numbers a line, line k = scan k) "
    "or TUM (stamp tx ty tz qx qy qz qw, matched by time).",
)
format_option = click.option(
    "--poses-format",
    type=click.Choice(["auto", "kitti", "tum"]),
    default="auto",
    show_default=True,
    help="Format of --poses (auto: by numbers a line).",
)
calib_option = click.option(
    "--calib",
    type=click.Path(path_type=Path),
    default=None,
    help="KITTI calib.txt: its Tr turns KITTI camera poses into lidar poses.",
)
topic_option = click.option(
    "--topic", default=None, help="PointCloud2 topic (default: the only one there is)."
)
gt_topic_option = click.option(
    "--gt-topic",
    default=None,
    help="Ground-truth topic: PoseStamped, Odometry or TF (tf2_msgs/TFMessage).",
)
child_option = click.option(
    "--gt-child-frame",
    default=None,
    help="With a TF --gt-topic: the child frame whose pose is the ground truth.",
)


def _done(report: Any) -> None:
    click.echo(
        f"{report.out}: {report.frames} frames, {report.points} points"
        f"{f' ({report.dropped_points} non-finite dropped)' if report.dropped_points else ''}, "
        f"ground truth: {'yes' if report.has_ground_truth else 'no'}, {report.seconds:.1f} s"
    )


@click.group()
def ingest() -> None:
    """Convert KITTI, ROS bags, MCAP recordings or scan folders into a sequence MCAP."""


@ingest.command("kitti")
@click.argument("root", type=click.Path(file_okay=False, path_type=Path))
@click.argument("seq")
@out_option
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
@click.argument("bag", type=click.Path(path_type=Path))
@out_option
@topic_option
@gt_topic_option
@child_option
@poses_option
@format_option
@calib_option
@name_option
def rosbag(
    bag: Path,
    out: Path,
    topic: str | None,
    gt_topic: str | None,
    gt_child_frame: str | None,
    poses: Path | None,
    poses_format: PoseFormat,
    calib: Path | None,
    name: str | None,
) -> None:
    """ROS 1 .bag file or ROS 2 bag folder (sqlite3 or mcap storage)."""
    from pipeline.sources import ingest_rosbag

    _done(
        ingest_rosbag(
            bag,
            out,
            topic=topic,
            gt_topic=gt_topic,
            gt_child_frame=gt_child_frame,
            poses=poses,
            poses_format=poses_format,
            calib=calib,
            name=name,
        )
    )


@ingest.command("folder")
@click.argument("folder", type=click.Path(file_okay=False, path_type=Path))
@out_option
@poses_option
@format_option
@click.option(
    "--times",
    type=click.Path(path_type=Path),
    default=None,
    help="Stamps file (seconds, one a line); default: TUM stamps, else frame / --rate.",
)
@click.option(
    "--rate", "rate_hz", type=float, default=10.0, show_default=True, help="Scan rate [Hz]."
)
@calib_option
@name_option
def folder(
    folder: Path,
    out: Path,
    poses: Path | None,
    poses_format: PoseFormat,
    times: Path | None,
    rate_hz: float,
    calib: Path | None,
    name: str | None,
) -> None:
    """Scan files (.bin / .pcd / .ply) of FOLDER in name order, one per frame."""
    from pipeline.sources import ingest_folder

    _done(
        ingest_folder(
            folder,
            out,
            poses=poses,
            poses_format=poses_format,
            times=times,
            calib=calib,
            rate_hz=rate_hz,
            name=name,
        )
    )


@ingest.command("mcap")
@click.argument("path", type=click.Path(dir_okay=False, path_type=Path))
@out_option
@topic_option
@gt_topic_option
@child_option
@poses_option
@format_option
@name_option
def mcap(
    path: Path,
    out: Path,
    topic: str | None,
    gt_topic: str | None,
    gt_child_frame: str | None,
    poses: Path | None,
    poses_format: PoseFormat,
    name: str | None,
) -> None:
    """Any MCAP with PointCloud2 messages (cdr or ros1 encoding), e.g. a ROS 2 recording."""
    from pipeline.sources import ingest_mcap

    _done(
        ingest_mcap(
            path,
            out,
            topic=topic,
            gt_topic=gt_topic,
            gt_child_frame=gt_child_frame,
            poses=poses,
            poses_format=poses_format,
            name=name,
        )
    )


@click.command("ingest-set")
@params_option
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for <NN>.mcap and index.json (data/kitti).")
def ingest_set(params_path: Path, out_dir: Path) -> None:
    """Ingest the KITTI sequences of the params section ``ingest`` (dvc stage)."""
    from pipeline.config import load_section
    from pipeline.sources.dataset import IngestSection, ingest_kitti_set

    section = load_section(params_path, "ingest", IngestSection)
    for report in ingest_kitti_set(section, out_dir):
        _done(report)
    click.echo(f"{out_dir / 'index.json'}: {len(section.train)} train, "
               f"{len(section.validation)} validation sequences")
