"""ROS 1 .bag files and ROS 2 bags (sqlite3 or mcap storage) through ``rosbags``.

The PointCloud2 topic is found by itself when the bag has exactly one. Scan stamps are the
header stamps (the bag's record time where a header stamp is zero). Ground truth, optional
(``pipeline.sources.poses.GroundTruthOptions``): a PoseStamped / PoseWithCovarianceStamped /
Odometry / TransformStamped topic (found by itself when the bag has exactly one), or a TF topic
with ``gt_child_frame``, or a pose file (TUM: matched by time; KITTI: line k = scan k, the
counts must match). ``extrinsic`` (pipeline.sources.poses.read_extrinsic) turns poses of another
frame into LiDAR poses. Stamped poses are interpolated to the scan stamps. Per-point time fields
are kept (pipeline.sources.pointtime).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.sequence import SequenceInfo
from pipeline.sources.base import (
    Frame,
    IngestReport,
    IntensityMode,
    input_files,
    write_sequence,
)
from pipeline.sources.poses import GroundTruth, GroundTruthOptions, lidar_ground_truth
from pipeline.sources.rosmsg import (
    POINTCLOUD2_TYPES,
    POSE_TYPES,
    TF_TYPE,
    cloud_frame,
    collect_poses,
    normalise_type,
    poses_of,
    stamp_ns,
)

log = logging.getLogger(__name__)


def bag_path(path: str | Path) -> Path:
    """The path rosbags opens: a ROS 1 .bag file or a ROS 2 bag folder (metadata.yaml)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such bag")
    if (
        path.is_file()
        and path.suffix in (".mcap", ".db3")
        and (path.parent / "metadata.yaml").is_file()
    ):
        return path.parent
    if path.is_file() and path.suffix == ".mcap":
        raise InputError(
            f"{path}: an MCAP file without a ROS 2 bag folder; use `adaptune ingest mcap` for it"
        )
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise InputError(f"{path}: not a ROS 2 bag folder (no metadata.yaml)")
    if not path.is_dir() and path.suffix != ".bag":
        raise InputError(f"{path}: not a ROS bag (expected a .bag file or a ROS 2 bag folder)")
    for p in sorted(path.iterdir()) if path.is_dir() else [path]:
        if not (p.is_file() or p.is_dir()):  # a FIFO or a device would block the reader
            raise InputError(f"{p}: is not a regular file (a bag is made of files)")
    return path


@contextmanager
def open_bag(path: Path) -> Iterator[Any]:
    """An open rosbags AnyReader; every rosbags failure becomes one InputError line."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{path}: cannot read bag ({type(exc).__name__}: {exc})") from None
    try:
        yield reader
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{path}: cannot read bag ({type(exc).__name__}: {exc})") from None
    finally:
        reader.close()


def pick_topic(
    available: dict[str, str], wanted: str | None, types: tuple[str, ...], what: str, kind: str
) -> str:
    """The one topic of ``types`` (or ``wanted``, checked) among topic -> type ``available``."""
    matching = sorted(t for t, ty in available.items() if normalise_type(ty) in types)
    if wanted is not None:
        if wanted not in available:
            raise InputError(
                f"{what}: no topic {wanted!r} (topics: {', '.join(sorted(available)) or 'none'})"
            )
        if normalise_type(available[wanted]) not in types:
            raise InputError(f"{what}: topic {wanted!r} is {available[wanted]}, not {kind}")
        return wanted
    if not matching:
        raise InputError(
            f"{what}: no {kind} topic (topics: "
            f"{', '.join(f'{t} [{ty}]' for t, ty in sorted(available.items())) or 'none'})"
        )
    if len(matching) > 1:
        raise InputError(
            f"{what}: {len(matching)} {kind} topics ({', '.join(matching)}); pick one with --topic"
        )
    return matching[0]


def pick_ground_truth_topic(available: dict[str, str], gt: GroundTruthOptions,
                            what: str) -> str | None:
    """The ground-truth topic among topic -> type ``available``: ``gt.gt_topic`` (checked);
    without it and without a pose file, the only pose, odometry or transform topic (TF aside:
    it needs a child frame) where there is exactly one, else None (several: one warning)."""
    if gt.gt_topic is not None:
        return pick_topic(available, gt.gt_topic, POSE_TYPES, what, "a pose, odometry or TF")
    if gt.poses is not None:
        return None
    found = sorted(t for t, ty in available.items()
                   if normalise_type(ty) in POSE_TYPES and normalise_type(ty) != TF_TYPE)
    if len(found) > 1:
        log.warning("%s: %d pose or odometry topics (%s): none taken as ground truth; pick one "
                    "with --gt-topic", what, len(found), ", ".join(found))
    if len(found) != 1:
        return None
    log.info("%s: ground truth from %s, the only pose or odometry topic", what, found[0])
    return found[0]


def ground_truth_note(topic: str | None, gt: GroundTruthOptions) -> str:
    """Where a recording's ground truth came from, for its metadata (``x.ground_truth``)."""
    if gt.poses is not None:
        return f"pose file {gt.poses}"
    if topic is None:
        return "none"
    return f"topic {topic}" + ("" if gt.gt_topic else " (found: the only pose topic)")


class RosbagSource:
    """PointCloud2 scans of a ROS 1 or ROS 2 bag."""

    name: ClassVar[str] = "rosbag"

    def __init__(
        self,
        bag: str | Path,
        topic: str | None = None,
        gt: GroundTruthOptions | None = None,
        name: str | None = None,
        sensor: str = "unknown",
    ) -> None:
        gt = gt or GroundTruthOptions()
        self.bag = bag_path(bag)
        bag_files = sorted(self.bag.iterdir()) if self.bag.is_dir() else [self.bag]
        self.inputs = input_files(*bag_files, *gt.files())
        self.seq_name = name or self.bag.stem
        self.sensor = sensor
        with open_bag(self.bag) as reader:
            available = {t: info.msgtype for t, info in reader.topics.items()}
            self.topic = pick_topic(
                available, topic, POINTCLOUD2_TYPES, str(self.bag), "sensor_msgs/PointCloud2"
            )
            self.count = sum(c.msgcount for c in reader.connections if c.topic == self.topic)
            self.gt_topic = pick_ground_truth_topic(available, gt, str(self.bag))
            self.gt: GroundTruth | None = None
            if self.gt_topic is not None:
                self.gt = self._topic_poses(reader, self.gt_topic, gt.gt_child_frame)
        self.gt = lidar_ground_truth(self.gt, gt.pose_file(), gt.extrinsic, self.count,
                                     f"{self.bag} {self.topic}")
        self.gt_note = ground_truth_note(self.gt_topic, gt)

    def _topic_poses(self, reader: Any, topic: str, child_frame: str | None) -> GroundTruth:
        what = f"{self.bag} {topic}"
        conns = [c for c in reader.connections if c.topic == topic]
        entries = []
        for conn, log_ns, raw in reader.messages(connections=conns):
            entries += poses_of(
                reader.deserialize(raw, conn.msgtype), conn.msgtype, log_ns, child_frame, what
            )
        stamps, T = collect_poses(entries, conns[0].msgtype, child_frame, what)
        return GroundTruth(what, stamps, T)

    def sequence_info(self) -> SequenceInfo:
        return SequenceInfo(
            name=self.seq_name, sensor=self.sensor,
            source=f"rosbag:{self.bag.resolve()}:{self.topic}",
            extra={"ground_truth": self.gt_note},
        )

    def expected_frames(self) -> int:
        return self.count

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        """The ground truth at the scans' stamps (their headers read, their points not)."""
        if self.gt is None:
            return None
        return self.gt.all_at(self.frame_stamps_ns())

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        """The scans' header stamps (their headers read, their points not)."""
        with open_bag(self.bag) as reader:
            conns = [c for c in reader.connections if c.topic == self.topic]
            stamps = [stamp_ns(reader.deserialize(raw, conn.msgtype), log_ns)
                      for conn, log_ns, raw in reader.messages(connections=conns)]
        return np.array(stamps, np.int64)

    def frames(self) -> Iterator[Frame]:
        with open_bag(self.bag) as reader:
            conns = [c for c in reader.connections if c.topic == self.topic]
            for k, (conn, log_ns, raw) in enumerate(reader.messages(connections=conns)):
                what = f"{self.bag} {self.topic} message {k}"
                yield cloud_frame(reader.deserialize(raw, conn.msgtype), log_ns, k, self.gt, what)


def ingest_rosbag(
    bag: str | Path,
    out: str | Path,
    topic: str | None = None,
    gt: GroundTruthOptions | None = None,
    name: str | None = None,
    sensor: str = "unknown",
    intensity: IntensityMode = "auto",
) -> IngestReport:
    """PointCloud2 scans of a ROS 1 / ROS 2 bag + optional ground truth -> sequence MCAP ``out``."""
    return write_sequence(RosbagSource(bag, topic, gt, name, sensor), out, intensity)
