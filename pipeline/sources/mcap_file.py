"""Any MCAP with sensor_msgs/PointCloud2 (a ROS 2 recording, a Foxglove export, another
sequence MCAP) normalised into a sequence MCAP.

Point clouds in ``cdr`` (ROS 2) or ``ros1`` encoding; the topic is found by itself when there
is exactly one. Stamps: header stamps (log time where zero). Ground truth, optional
(``pipeline.sources.poses.GroundTruthOptions``, as a bag's): a pose, odometry or TF topic in
the same file (interpolated to the scan stamps; found by itself where there is exactly one
pose or odometry topic), or a pose file.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.io_utils import input_file
from pipeline.sequence import SequenceInfo, mcap_errors
from pipeline.sources.base import (
    Frame,
    IngestReport,
    IntensityMode,
    input_files,
    write_sequence,
)
from pipeline.sources.poses import GroundTruth, GroundTruthOptions, lidar_ground_truth
from pipeline.sources.rosbag import ground_truth_note, pick_ground_truth_topic, pick_topic
from pipeline.sources.rosmsg import (
    POINTCLOUD2_TYPES,
    cloud_frame,
    collect_poses,
    normalise_type,
    poses_of,
    stamp_ns,
)

ENCODINGS = ("cdr", "ros1")


@contextmanager
def open_mcap(path: Path) -> Iterator[tuple[Any, Any]]:
    """(reader, summary) of an MCAP file; any failure becomes one InputError line."""
    from mcap.reader import make_reader

    input_file(path, "MCAP file")
    with open(path, "rb") as fh, mcap_errors(path):
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            raise InputError(
                f"{path}: corrupt or truncated MCAP (no summary section; "
                "`mcap recover` can rebuild it)"
            )
        yield reader, summary


class _Decoder:
    """Deserialises messages of one channel (rosbags typestore, cdr or ros1)."""

    def __init__(self, schema: Any, encoding: str, what: str) -> None:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        if encoding not in ENCODINGS:
            raise InputError(
                f"{what}: message encoding {encoding!r} is not supported ({', '.join(ENCODINGS)})"
            )
        self.encoding, self.what = encoding, what
        self.msgtype = normalise_type(schema.name)
        self.store = get_typestore(Stores.ROS2_HUMBLE if encoding == "cdr" else Stores.ROS1_NOETIC)
        if self.msgtype not in self.store.fielddefs:
            try:
                self.store.register(get_types_from_msg(schema.data.decode(), self.msgtype))
            except Exception as exc:
                raise InputError(
                    f"{what}: cannot parse the schema of {schema.name} ({exc})"
                ) from None

    def message(self, data: bytes) -> Any:
        if self.encoding == "cdr":
            return self.store.deserialize_cdr(data, self.msgtype)
        return self.store.deserialize_ros1(data, self.msgtype)

    def checked(self, data: bytes, what: str) -> Any:
        """The deserialised message; InputError naming ``what`` for bytes that are not one."""
        try:
            return self.message(data)
        except Exception as exc:
            raise InputError(f"{what}: not a valid {self.msgtype} message "
                             f"({type(exc).__name__}: {exc})") from None


class McapSource:
    """PointCloud2 scans of any MCAP file."""

    name: ClassVar[str] = "mcap"

    def __init__(
        self,
        path: str | Path,
        topic: str | None = None,
        gt: GroundTruthOptions | None = None,
        name: str | None = None,
        sensor: str = "unknown",
    ) -> None:
        gt = gt or GroundTruthOptions()
        self.path = Path(path)
        self.inputs = input_files(path, *gt.files())
        self.seq_name = name or self.path.stem
        self.sensor = sensor
        self.gt: GroundTruth | None = None
        with open_mcap(self.path) as (reader, summary):
            channels = {ch.topic: ch for ch in summary.channels.values()}
            available = {
                t: summary.schemas[ch.schema_id].name if ch.schema_id in summary.schemas else ""
                for t, ch in channels.items()
            }
            self.topic = pick_topic(
                available, topic, POINTCLOUD2_TYPES, str(self.path), "sensor_msgs/PointCloud2"
            )
            self.channel = channels[self.topic]
            self.schema = summary.schemas[self.channel.schema_id]
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
            self.count = int(counts.get(self.channel.id, 0)) or None
            self.gt_topic = pick_ground_truth_topic(available, gt, str(self.path))
            if self.gt_topic is not None:
                self.gt = self._topic_poses(reader, summary, channels[self.gt_topic],
                                            gt.gt_child_frame)
        self.gt = lidar_ground_truth(self.gt, gt.pose_file(), gt.extrinsic, self.count or 0,
                                     f"{self.path} {self.topic}")
        self.gt_note = ground_truth_note(self.gt_topic, gt)

    def _topic_poses(
        self, reader: Any, summary: Any, channel: Any, child_frame: str | None
    ) -> GroundTruth:
        what = f"{self.path} {channel.topic}"
        schema = summary.schemas[channel.schema_id]
        dec = _Decoder(schema, channel.message_encoding, what)
        entries = []
        for _, _, msg in reader.iter_messages(topics=[channel.topic]):
            entries += poses_of(dec.message(msg.data), dec.msgtype, msg.log_time, child_frame, what)
        stamps, T = collect_poses(entries, dec.msgtype, child_frame, what)
        return GroundTruth(what, stamps, T)

    def sequence_info(self) -> SequenceInfo:
        return SequenceInfo(
            name=self.seq_name, sensor=self.sensor,
            source=f"mcap:{self.path.resolve()}:{self.topic}",
            extra={"ground_truth": self.gt_note},
        )

    def expected_frames(self) -> int | None:
        return self.count

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        """The ground truth at the scans' stamps (their headers read, their points not)."""
        if self.gt is None:
            return None
        return self.gt.all_at(self.frame_stamps_ns())

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        """The scans' header stamps (their headers read, their points not)."""
        dec = _Decoder(self.schema, self.channel.message_encoding, f"{self.path} {self.topic}")
        with open_mcap(self.path) as (reader, _):
            stamps = [stamp_ns(dec.checked(msg.data, f"{self.path} {self.topic} message {k}"),
                               msg.log_time)
                      for k, (_, _, msg) in enumerate(reader.iter_messages(topics=[self.topic]))]
        return np.array(stamps, np.int64)

    def frames(self) -> Iterator[Frame]:
        dec = _Decoder(self.schema, self.channel.message_encoding, f"{self.path} {self.topic}")
        with open_mcap(self.path) as (reader, _):
            for k, (_, _, msg) in enumerate(reader.iter_messages(topics=[self.topic])):
                what = f"{self.path} {self.topic} message {k}"
                yield cloud_frame(dec.checked(msg.data, what), msg.log_time, k, self.gt, what)


def ingest_mcap(
    path: str | Path,
    out: str | Path,
    topic: str | None = None,
    gt: GroundTruthOptions | None = None,
    name: str | None = None,
    sensor: str = "unknown",
    intensity: IntensityMode = "auto",
) -> IngestReport:
    """PointCloud2 scans of any MCAP + optional ground truth -> sequence MCAP ``out``."""
    return write_sequence(McapSource(path, topic, gt, name, sensor), out, intensity)
