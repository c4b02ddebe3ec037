"""The sequence MCAP: one file per LiDAR sequence, the format every later stage reads.

Layout (docs/design.md, "Formats"):
- ``/lidar/points``: sensor_msgs/msg/PointCloud2 (float32 x, y, z, intensity), CDR;
- ``/ground_truth/pose``: geometry_msgs/msg/PoseStamped, T_world_lidar, where known;
- ``/tf``: tf2_msgs/msg/TFMessage, ``world`` -> ``lidar`` from the same ground truth (so a
  viewer such as Foxglove places the scans in the world), and any transform added with
  ``add_tf`` (e.g. an estimate's frame);
- metadata ``adaptune.sequence``: name, sensor, source, frame_count, labels, schema_version,
  and length_m, jump_limit_m where the sequence has them of its own (``SequenceInfo``);
- metadata ``adaptune.frames``: the log times of the frames, so frame k is one seek away.
Log time = sensor stamp [ns]; frames are 0..N-1 in log-time order. Chunked, indexed, zstd by
default (``Compression``: ``none`` for scratch data read again at once, such as the verdict's
tuning suite: x0.35 the write, x0.5 the read, x1.35 the size of an HDL-64E scan).
Small channels (poses, parameters) are buffered and written after the scans, in chunks of
their own, so reading the ground truth never decompresses a scan.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import AdaptuneError, ConfigError, InputError, SchemaError
from pipeline.geometry import MAX_POSITION_M, refuse_non_rotations
from pipeline.io_utils import atomic_path, check_plain_name, input_file
from pipeline.ros2_cdr import (
    POINTCLOUD2,
    POSE_STAMPED,
    TF_MESSAGE,
    TIME_FIELD,
    cloud_field,
    cloud_to_xyzi,
    decode_pointcloud2,
    decode_pose_stamped,
    encode_pointcloud2,
    encode_pose_stamped,
    encode_tf,
    schema_text,
)
from pipeline.stamps import check_stamp_ns
from schemas import SCHEMA_VERSION

log = logging.getLogger(__name__)

POINTS_TOPIC = "/lidar/points"
GT_TOPIC = "/ground_truth/pose"
TF_TOPIC = "/tf"
WORLD_FRAME = "world"
LIDAR_FRAME = "lidar"
META_SEQUENCE = "adaptune.sequence"
META_FRAMES = "adaptune.frames"
CHANNEL_TYPES = {POINTS_TOPIC: POINTCLOUD2, GT_TOPIC: POSE_STAMPED}
"""The message type of every channel SequenceReader decodes."""
Compression = Literal["zstd", "none"]
"""How a sequence's chunks are compressed (the MCAP compressions a reader takes)."""
COMPRESSIONS: tuple[str, ...] = get_args(Compression)


@dataclass(frozen=True)
class Scan:
    """One LiDAR frame.

    points_lidar: (N, 4) float32 x, y, z [m] in the sensor frame and intensity.
    T_world_lidar: (4, 4) float64 ground-truth pose, or None where unknown.
    time_s: (N,) float32 per-point time [s] relative to ``stamp_ns``, or None (no per-point
    time: an instantaneous scan, or a recording without it).
    """

    frame: int
    stamp_ns: int
    points_lidar: NDArray[np.float32]
    T_world_lidar: NDArray[np.float64] | None = None
    time_s: NDArray[np.float32] | None = None

    @property
    def xyz(self) -> NDArray[np.float32]:
        """(N, 3) float32 points in the sensor frame [m]."""
        return self.points_lidar[:, :3]


@dataclass(frozen=True)
class EnvLabel:
    """Environment label of the frames ``start`` .. ``end`` (inclusive)."""

    start: int
    end: int
    label: str


OWN_SETTINGS = ("length_m", "jump_limit_m")
"""The settings [m] a sequence may have of its own (``SequenceInfo``), each winning over the
stages' (base.length_m, trials.jump_limit_m) and recorded only where given."""


@dataclass
class SequenceInfo:
    """What the ``adaptune.sequence`` metadata record says about a sequence.

    ``length_m``: the RTE length L [m] this sequence is scored at (a ``data`` source's
    ``length_m``), which wins over the stages' ``base.length_m`` (``scored_length_m``); None:
    it has none of its own (the record then has no such key, as before it existed).
    ``jump_limit_m``: likewise the frame-to-frame translation [m] above which a trial's
    odometry on this sequence has failed (a ``data`` source's ``jump_limit_m``), which wins
    over ``trials.jump_limit_m``; None: none of its own, no key."""

    name: str
    sensor: str = "unknown"
    source: str = "unknown"
    labels: list[EnvLabel] = field(default_factory=list)
    frame_count: int = 0
    schema_version: str = SCHEMA_VERSION
    extra: dict[str, str] = field(default_factory=dict)
    length_m: float | None = None
    jump_limit_m: float | None = None

    def to_record(self) -> dict[str, str]:
        rec = {
            "name": self.name, "sensor": self.sensor, "source": self.source,
            "frame_count": str(self.frame_count), "schema_version": self.schema_version,
            "labels": json.dumps([[x.start, x.end, x.label] for x in self.labels]),
        }
        for key in OWN_SETTINGS:
            if getattr(self, key) is not None:
                rec[key] = repr(float(getattr(self, key)))
        rec.update({f"x.{k}": v for k, v in self.extra.items()})
        return rec

    @classmethod
    def from_record(cls, rec: dict[str, str], what: str) -> SequenceInfo:
        try:
            labels = [EnvLabel(int(a), int(b), str(c)) for a, b, c in json.loads(rec["labels"])]
            info = cls(
                name=rec["name"], sensor=rec["sensor"], source=rec["source"], labels=labels,
                frame_count=int(rec["frame_count"]), schema_version=rec["schema_version"],
                extra={k[2:]: v for k, v in rec.items() if k.startswith("x.")},
                **{key: float(rec[key]) for key in OWN_SETTINGS if key in rec},
            )
        except (KeyError, ValueError, TypeError) as exc:
            raise SchemaError(f"{what}: malformed '{META_SEQUENCE}' metadata ({exc})") from exc
        for key in OWN_SETTINGS:
            value = getattr(info, key)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise SchemaError(f"{what}: malformed '{META_SEQUENCE}' metadata ({key} must be "
                                  f"a finite number > 0 m, got {rec[key]!r})")
        return info

    def scored_length_m(self, default_m: float) -> float:
        """The RTE length L [m] this sequence is scored at (``scored_length_m``)."""
        return scored_length_m(self.length_m, default_m)

    def label_of(self, frame: int) -> str | None:
        """Environment label of ``frame``, or None."""
        for lab in self.labels:
            if lab.start <= frame <= lab.end:
                return lab.label
        return None


def scored_length_m(own_m: float | None, default_m: float) -> float:
    """The RTE length L [m] a sequence is scored at: its own (``own_m``,
    ``SequenceInfo.length_m``), else ``default_m`` (base.length_m, or a command's
    ``--length``): docs/design.md, "Stages"."""
    return default_m if own_m is None else own_m


MAX_COORDINATE_M = 10_000.0
"""A LiDAR return farther than 10 km from the sensor is not a measurement: the file is not
what it claims to be (random bytes read as float32 reach 3e38 m)."""


def finite_points(points: NDArray[np.float32], what: str) -> NDArray[np.bool_]:
    """(N,) mask of the points with finite coordinates.

    Raises InputError naming ``what`` when nothing finite is left, or when a coordinate is
    beyond MAX_COORDINATE_M (not a LiDAR scan).
    """
    xyz = points[:, :3]
    if len(xyz) and max(float(xyz.max()), -float(xyz.min())) <= MAX_COORDINATE_M:
        return np.ones(len(xyz), bool)  # the common case, in two passes (NaN fails the test)
    ok: NDArray[np.bool_] = np.asarray(np.isfinite(xyz).all(axis=1))
    if not ok.any():
        raise InputError(f"{what}: empty scan (no finite points of {points.shape[0]})")
    far_mask = (np.abs(np.where(ok[:, None], points[:, :3], 0)) > MAX_COORDINATE_M).any(axis=1)
    if far_mask.any():
        far = float(np.abs(points[far_mask, :3]).max())
        raise InputError(f"{what}: {int(far_mask.sum())} points have a coordinate beyond "
                         f"{MAX_COORDINATE_M:g} m (up to {far:.3g} m): not a LiDAR scan in "
                         "metres (wrong format or random bytes?)")
    return ok


class SequenceWriter:
    """Write a sequence MCAP atomically: use as a context manager, ``add`` frames in order.
    ``compression``: of its chunks (``Compression``); readers take either. ``points`` False
    leaves the scans out (``add`` checks them and writes the rest of the frame): a record of a
    run, such as ``adaptune live``'s, not a sequence the reader gives scans of."""

    def __init__(self, path: str | Path, info: SequenceInfo, chunk_size: int = 4 << 20,
                 compression: Compression = "zstd", points: bool = True) -> None:
        check_plain_name(info.name, "the sequence name")  # later stages name files after it
        if compression not in COMPRESSIONS:
            raise ConfigError(f"compression must be one of {', '.join(COMPRESSIONS)}, got "
                              f"{compression!r}")
        self.path = Path(path)
        self.info = info
        self.chunk_size = chunk_size
        self.compression = compression
        self.points = points
        self.stamps_ns: list[int] = []
        self.dropped_points = 0
        self._poses: dict[str, list[tuple[int, bytes]]] = {}
        self._tf: list[tuple[int, bytes]] = []
        self._ros2: dict[tuple[str, str], list[tuple[int, bytes]]] = {}
        self._json: dict[str, tuple[dict[str, Any], list[tuple[int, bytes]]]] = {}

    def __enter__(self) -> SequenceWriter:
        from mcap.writer import CompressionType, Writer

        with contextlib.ExitStack() as stack:  # on an error here: file closed, temp removed
            self._tmp = stack.enter_context(atomic_path(self.path))
            self._fh = stack.enter_context(open(self._tmp, "wb"))
            self._w = Writer(self._fh, chunk_size=self.chunk_size,
                             compression=CompressionType[self.compression.upper()])
            self._w.start(profile="ros2", library="adaptune")
            self._schemas = {
                t: self._w.register_schema(t, "ros2msg", schema_text(t).encode())
                for t in (POINTCLOUD2, POSE_STAMPED, TF_MESSAGE)
            }
            if self.points:
                self._points_ch = self._w.register_channel(POINTS_TOPIC, "cdr",
                                                           self._schemas[POINTCLOUD2])
            self._outputs = stack.pop_all()
        return self

    def add(self, stamp_ns: int, points_lidar: NDArray[np.float32],
            T_world_lidar: NDArray[np.float64] | None = None,
            time_s: NDArray[np.float32] | None = None) -> int:
        """Append one frame; returns its index. Non-finite points are dropped and counted.

        points_lidar: (N, 3) or (N, 4) float [m]; T_world_lidar: (4, 4) or None; time_s: (N,)
        per-point time [s] relative to ``stamp_ns``, or None.
        """
        frame = len(self.stamps_ns)
        what = f"{self.info.name} frame {frame}"
        stamp_ns = check_stamp_ns(stamp_ns, what)
        if self.stamps_ns and stamp_ns <= self.stamps_ns[-1]:
            raise InputError(f"{what}: stamp {stamp_ns} ns is not after the previous "
                             f"{self.stamps_ns[-1]} ns (frames must be in time order)")
        pts = np.asarray(points_lidar, dtype=np.float32)
        if pts.ndim != 2 or pts.shape[1] not in (3, 4):
            raise InputError(f"{what}: points must be (N, 3) or (N, 4), got {pts.shape}")
        if pts.shape[1] == 3:
            pts = np.concatenate([pts, np.zeros((len(pts), 1), np.float32)], axis=1)
        ok = finite_points(pts, what)
        if time_s is not None:
            time_s = np.asarray(time_s, np.float32)
            if time_s.shape != (len(pts),) or not np.isfinite(time_s[ok]).all():
                raise InputError(f"{what}: per-point times must be {len(pts)} finite values, "
                                 f"got shape {time_s.shape}")
        dropped = int(len(pts) - ok.sum())
        if dropped:
            pts = pts[ok]
            time_s = None if time_s is None else time_s[ok]
        self.dropped_points += dropped
        if self.points:
            self._w.add_message(self._points_ch, log_time=stamp_ns, publish_time=stamp_ns,
                                data=encode_pointcloud2(stamp_ns, pts, time_s=time_s),
                                sequence=frame)
        if T_world_lidar is not None:
            T = np.asarray(T_world_lidar, dtype=np.float64)
            if T.shape != (4, 4) or not np.isfinite(T).all():
                raise InputError(f"{what}: ground-truth pose is not a finite 4x4 matrix")
            refuse_non_rotations(T[None, :3, :3], f"{what}: ground truth")
            if np.abs(T[:3, 3]).max() > MAX_POSITION_M:
                raise InputError(f"{what}: ground-truth position {T[:3, 3].tolist()} m is "
                                 f"beyond {MAX_POSITION_M:g} m: not a trajectory on Earth")
            self.add_pose(GT_TOPIC, stamp_ns, T)
            self.add_tf(stamp_ns, WORLD_FRAME, LIDAR_FRAME, T)
        self.stamps_ns.append(stamp_ns)
        return frame

    def add_pose(self, topic: str, stamp_ns: int, T_world_x: NDArray[np.float64]) -> None:
        """Queue a PoseStamped on ``topic`` (written after the scans, in its own chunks)."""
        msg = encode_pose_stamped(stamp_ns, T_world_x)
        self._poses.setdefault(topic, []).append((int(stamp_ns), msg))

    def add_tf(self, stamp_ns: int, parent: str, child: str,
               T_parent_child: NDArray[np.float64]) -> None:
        """Queue a ``/tf`` transform ``parent`` -> ``child`` (T_parent_child (4, 4)) at
        ``stamp_ns`` (written after the scans, in its own chunks)."""
        self._tf.append((int(stamp_ns), encode_tf(stamp_ns, parent, child, T_parent_child)))

    def add_ros2(self, topic: str, msgtype: str, stamp_ns: int, data: bytes) -> None:
        """Queue CDR bytes of ``msgtype`` (one of ``pipeline.ros2_cdr.MESSAGE_TYPES``) on
        ``topic`` (written after the scans, in its own chunks)."""
        self._ros2.setdefault((topic, msgtype), []).append((int(stamp_ns), data))

    def add_json(self, topic: str, stamp_ns: int, message: dict[str, Any],
                 json_schema: dict[str, Any]) -> None:
        """Queue a JSON message on ``topic`` with its JSON Schema (Foxglove plots its fields)."""
        _, msgs = self._json.setdefault(topic, (json_schema, []))
        msgs.append((int(stamp_ns), json.dumps(message).encode()))

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        """Finish the file and move it onto ``path``; on any error, in the ``with`` block or in
        finishing, the temporary file is removed and ``path`` stays as it was."""
        if exc_type is not None:
            self._outputs.__exit__(exc_type, exc, tb)
            return
        with self._outputs:  # sees an exception of _finish: then the temporary file goes
            self._finish()

    def _finish(self) -> None:
        if not self.stamps_ns:
            raise InputError(f"{self.info.name}: no frames to write")
        self._w.flush()  # close the last scan chunk: small channels get chunks of their own
        for topic, msgs in self._poses.items():
            ch = self._w.register_channel(topic, "cdr", self._schemas[POSE_STAMPED])
            for i, (t, data) in enumerate(msgs):
                self._w.add_message(ch, log_time=t, publish_time=t, data=data, sequence=i)
        if self._tf:
            ch = self._w.register_channel(TF_TOPIC, "cdr", self._schemas[TF_MESSAGE])
            for i, (t, data) in enumerate(sorted(self._tf, key=lambda m: m[0])):
                self._w.add_message(ch, log_time=t, publish_time=t, data=data, sequence=i)
        for (topic, msgtype), msgs in self._ros2.items():
            if msgtype not in self._schemas:
                self._schemas[msgtype] = self._w.register_schema(
                    msgtype, "ros2msg", schema_text(msgtype).encode())
            ch = self._w.register_channel(topic, "cdr", self._schemas[msgtype])
            for i, (t, data) in enumerate(msgs):
                self._w.add_message(ch, log_time=t, publish_time=t, data=data, sequence=i)
        for topic, (schema, msgs) in self._json.items():
            sid = self._w.register_schema(topic.strip("/").replace("/", "."), "jsonschema",
                                          json.dumps(schema).encode())
            ch = self._w.register_channel(topic, "json", sid)
            for i, (t, data) in enumerate(msgs):
                self._w.add_message(ch, log_time=t, publish_time=t, data=data, sequence=i)
        self.info.frame_count = len(self.stamps_ns)
        self._w.add_metadata(META_SEQUENCE, self.info.to_record())
        self._w.add_metadata(META_FRAMES, {"stamps_ns": " ".join(map(str, self.stamps_ns))})
        self._w.finish()
        if self.dropped_points:
            log.warning("%s: dropped %d non-finite points", self.info.name, self.dropped_points)


@contextlib.contextmanager
def mcap_errors(path: str | Path) -> Iterator[None]:
    """The block's failures while reading the MCAP at ``path`` as one InputError line: the
    mcap reader raises many types for a damaged or truncated file (adaptune's own errors pass
    through as they are)."""
    try:
        yield
    except AdaptuneError:
        raise
    except Exception as exc:
        raise InputError(
            f"{path}: corrupt or truncated MCAP ({type(exc).__name__}: {exc})") from exc


class SequenceReader:
    """Random access to the frames of a sequence MCAP. Use as a context manager or ``close()``.

    ``len(reader)`` frames; ``reader[k]`` -> Scan; iteration yields Scans with ground truth.
    """

    def __init__(self, path: str | Path) -> None:
        from mcap.reader import make_reader

        self.path = Path(path)
        input_file(self.path, "sequence file")
        self._fh = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        try:
            with mcap_errors(self.path):
                self._reader = make_reader(self._fh, validate_crcs=True)
                summary = self._reader.get_summary()
                meta = {m.name: m.metadata for m in self._reader.iter_metadata()}
        except InputError:
            self.close()
            raise
        if summary is None:
            self.close()
            raise InputError(f"{self.path}: corrupt or truncated MCAP (no summary section)")
        if META_SEQUENCE not in meta or META_FRAMES not in meta:
            self.close()
            raise SchemaError(f"{self.path}: not an adaptune sequence MCAP (no '{META_SEQUENCE}' "
                              "metadata); normalise it with `adaptune ingest mcap`")
        self.info = SequenceInfo.from_record(meta[META_SEQUENCE], str(self.path))
        if self.info.schema_version.split(".")[0] != SCHEMA_VERSION.split(".")[0]:
            self.close()
            raise SchemaError(f"{self.path}: schema version {self.info.schema_version}, "
                              f"this adaptune reads {SCHEMA_VERSION}")
        self._check_channels(summary)
        self.stamps_ns = self._frame_stamps(meta[META_FRAMES])
        self.topics = {ch.topic for ch in summary.channels.values()}
        self._gt: NDArray[np.float64] | bool | None = False

    def _check_channels(self, summary: Any) -> None:
        """SchemaError unless the channels this reader decodes declare what it decodes them
        as: ``POINTS_TOPIC`` PointCloud2 and ``GT_TOPIC`` PoseStamped, both in cdr (bytes of
        another type could decode as either by chance)."""
        for ch in summary.channels.values():
            expected = CHANNEL_TYPES.get(ch.topic)
            if expected is None:
                continue
            schema = summary.schemas.get(ch.schema_id)
            declared = schema.name if schema is not None else "no schema"
            if declared != expected or ch.message_encoding != "cdr":
                self.close()
                raise SchemaError(f"{self.path}: channel {ch.topic} declares {declared} "
                                  f"({ch.message_encoding}); a sequence MCAP's is {expected} "
                                  "(cdr)")

    def _frame_stamps(self, record: dict[str, str]) -> NDArray[np.int64]:
        """The frame stamps [ns] of the ``adaptune.frames`` metadata, checked: integers in
        range, strictly increasing, one per frame of ``adaptune.sequence``."""
        try:
            stamps = [check_stamp_ns(int(s), "") for s in record["stamps_ns"].split()]
        except (KeyError, ValueError, InputError) as exc:
            self.close()
            raise SchemaError(f"{self.path}: malformed '{META_FRAMES}' metadata (stamps_ns "
                              f"must be integer ns in [0, 2^31) s: {exc})") from None
        out = np.array(stamps, np.int64)
        if len(out) != self.info.frame_count or np.any(np.diff(out) <= 0):
            self.close()
            raise SchemaError(f"{self.path}: malformed '{META_FRAMES}' metadata ({len(out)} "
                              f"stamps for {self.info.frame_count} frames, must be strictly "
                              "increasing)")
        return out

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def __enter__(self) -> SequenceReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the file handle."""
        self._fh.close()

    def _messages(self, topics: list[str], start: int | None = None, end: int | None = None):
        with mcap_errors(self.path):
            yield from self._reader.iter_messages(
                topics=topics, starting_at=start, ending_before=end
            )

    def _scan(self, frame: int, stamp_ns: int, data: bytes,
              gt: NDArray[np.float64] | None) -> Scan:
        what = f"{self.path} frame {frame}"
        msg = decode_pointcloud2(data, what)
        t = cloud_field(msg, (TIME_FIELD.name,), what)
        return Scan(frame, stamp_ns, cloud_to_xyzi(msg, what),
                    None if gt is None else gt[frame],
                    None if t is None else t[1].astype(np.float32))

    @property
    def has_ground_truth(self) -> bool:
        return GT_TOPIC in self.topics

    def ground_truth(self) -> NDArray[np.float64] | None:
        """(N, 4, 4) T_world_lidar of every frame, or None when the sequence has none."""
        if self._gt is False:
            self._gt = None
            if self.has_ground_truth:
                poses = {}
                for _, _, msg in self._messages([GT_TOPIC]):
                    what = f"{self.path} {GT_TOPIC}"
                    poses[msg.log_time] = decode_pose_stamped(msg.data, what)[1]
                missing = [int(s) for s in self.stamps_ns if int(s) not in poses]
                if missing:
                    raise InputError(
                        f"{self.path}: {len(missing)} frames have no ground-truth pose"
                    )
                self._gt = np.stack([poses[int(s)] for s in self.stamps_ns])
        return self._gt  # type: ignore[return-value]

    def require_ground_truth(self, purpose: str) -> NDArray[np.float64]:
        """(N, 4, 4) T_world_lidar of every frame (``ground_truth``); InputError naming the file
        and ``purpose`` (what it is needed for: "to export") when the sequence has none."""
        gt = self.ground_truth()
        if gt is None:
            raise InputError(f"{self.path}: no ground truth {purpose}")
        return gt

    def __getitem__(self, frame: int) -> Scan:
        n = len(self)
        if not -n <= frame < n:
            raise IndexError(f"{self.path}: frame {frame} out of range 0..{n - 1}")
        frame %= n
        t = int(self.stamps_ns[frame])
        for _, _, msg in self._messages([POINTS_TOPIC], t, t + 1):
            return self._scan(frame, t, msg.data, self.ground_truth())
        raise InputError(f"{self.path}: frame {frame} (stamp {t} ns) has no point cloud")

    def __iter__(self) -> Iterator[Scan]:
        gt = self.ground_truth()
        index = {int(s): i for i, s in enumerate(self.stamps_ns)}
        count = 0
        for _, _, msg in self._messages([POINTS_TOPIC]):
            frame = index.get(msg.log_time)
            if frame is None:
                raise InputError(
                    f"{self.path}: point cloud at {msg.log_time} ns is not a listed frame"
                )
            count += 1
            yield self._scan(frame, msg.log_time, msg.data, gt)
        if count != len(self):
            raise InputError(f"{self.path}: {count} point clouds for {len(self)} frames")

    def iter_every_chunk(self) -> Iterator[tuple[str, Any]]:
        """(topic, message) of every message of every chunk of the file, each chunk's CRC
        checked; InputError naming the file on a mismatch.

        The other methods check the CRCs of the chunks they read and no others: the ground
        truth's (``export``, ``metric``) lives in chunks of its own, apart from the scans'.
        ``adaptune info`` reads the file through this (docs/design.md, "Inputs": which command
        checks which chunks, and why: bench/bench_crc.py)."""
        with mcap_errors(self.path):
            for _, channel, msg in self._reader.iter_messages():
                yield channel.topic, msg

    def iter_topic_json(self, topic: str) -> Iterator[tuple[int, dict[str, Any]]]:
        """(stamp_ns, message) of a JSON channel such as ``/adaptune/params``."""
        for _, _, msg in self._messages([topic]):
            yield msg.log_time, json.loads(msg.data)

    def iter_topic_poses(self, topic: str) -> Iterator[tuple[int, NDArray[np.float64]]]:
        """(stamp_ns, (4, 4) pose) of a PoseStamped channel such as ``/odometry/pose``."""
        for _, _, msg in self._messages([topic]):
            yield decode_pose_stamped(msg.data, f"{self.path} {topic}")


def as_recorded(T_world_lidar: NDArray[np.float64]) -> NDArray[np.float64]:
    """(4, 4) the ground-truth pose a sequence MCAP gives back for ``T_world_lidar``: its
    PoseStamped (a quaternion) decoded again, whose rotation may differ in its last bit."""
    return decode_pose_stamped(encode_pose_stamped(0, T_world_lidar), "a pose")[1]


def read_info(path: str | Path) -> SequenceInfo:
    """The ``SequenceInfo`` of the sequence MCAP at ``path`` (its own RTE length and jump
    limit among them); its metadata read, not its scans."""
    with SequenceReader(path) as reader:
        return reader.info


def read_ground_truth(path: str | Path, purpose: str) -> NDArray[np.float64]:
    """(N, 4, 4) ground-truth T_world_lidar of the sequence MCAP at ``path``
    (``SequenceReader.require_ground_truth``: InputError naming ``purpose`` when it has none)."""
    with SequenceReader(path) as reader:
        return reader.require_ground_truth(purpose)
