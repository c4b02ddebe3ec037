"""ROS 2 messages of the sequence MCAP in CDR, through mcap_ros2 (mcap-ros2-support).

The codecs are the library's, built from the ROS 2 ``.msg`` texts in ``schemas/ros2/`` (the
same texts the MCAP stores as its schemas), so every ROS 2 tool decodes what adaptune writes.
``make bench`` (bench/bench_cdr.py) compares them with the hand-written struct codec they
replaced: equal speed, byte-identical output (issue 18, item 6).

Here too: the PointCloud2 layout -> (N, 4) float32 x, y, z, intensity (any field layout), and
poses <-> PoseStamped / TFMessage.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
PARAMETER_EVENT = "rcl_interfaces/msg/ParameterEvent"
PATH = "nav_msgs/msg/Path"
MESSAGE_TYPES = (POINTCLOUD2, POSE_STAMPED, TF_MESSAGE, PARAMETER_EVENT, PATH)

# sensor_msgs/PointField datatype -> numpy dtype
POINTFIELD_DTYPES: dict[int, np.dtype] = {
    1: np.dtype(np.int8), 2: np.dtype(np.uint8), 3: np.dtype(np.int16),
    4: np.dtype(np.uint16), 5: np.dtype(np.int32), 6: np.dtype(np.uint32),
    7: np.dtype(np.float32), 8: np.dtype(np.float64),
}


@dataclass(frozen=True)
class PointField:
    """One field of a PointCloud2: byte ``offset`` in a point, ``datatype`` 1-8, ``count``."""

    name: str
    offset: int
    datatype: int
    count: int = 1


XYZI_FIELDS = (
    PointField("x", 0, 7), PointField("y", 4, 7), PointField("z", 8, 7),
    PointField("intensity", 12, 7),
)
TIME_FIELD = PointField("time", 16, 7)
"""Per-point time of a sequence MCAP scan: float32 seconds relative to the header stamp (the
Velodyne driver's convention), present when the input had per-point time."""


def schema_text(msgtype: str) -> str:
    """The concatenated ROS 2 ``.msg`` definition of ``msgtype`` (schemas/ros2/)."""
    from schemas import read_text

    if msgtype not in MESSAGE_TYPES:
        raise ValueError(f"no schema text for {msgtype!r} (known: {', '.join(MESSAGE_TYPES)})")
    pkg, _, name = msgtype.split("/")
    return read_text(f"ros2/{pkg}__{name}.msg")


@functools.cache
def _codec(msgtype: str) -> tuple[Callable[[Any], bytes], Callable[[bytes], Any]]:
    """(encoder, decoder) of ``msgtype`` built by mcap_ros2 from its schema text."""
    from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

    text = schema_text(msgtype)
    return serialize_dynamic(msgtype, text)[msgtype], generate_dynamic(msgtype, text)[msgtype]


def encode(msgtype: str, message: dict[str, Any]) -> bytes:
    """CDR bytes of ``message`` (nested dicts with the .msg field names) as ``msgtype``."""
    return _codec(msgtype)[0](message)


def decode(msgtype: str, data: bytes | memoryview, what: str) -> Any:
    """The decoded ``msgtype`` message (attributes named as in the .msg); InputError names
    ``what`` when the bytes are not such a message."""
    try:
        return _codec(msgtype)[1](bytes(data))
    except Exception as exc:  # the library raises struct/index/unicode errors on bad bytes
        raise InputError(f"{what}: not a valid {msgtype} message "
                         f"({type(exc).__name__}: {exc})") from None


def header(stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """A std_msgs/Header dict of ``stamp_ns`` [ns] (>= 0)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}


def header_stamp_ns(msg: Any) -> int:
    """The header stamp [ns] of a decoded message."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def encode_pointcloud2(
    stamp_ns: int, points_xyzi: NDArray[np.float32], frame_id: str = "lidar",
    time_s: NDArray[np.float32] | None = None,
) -> bytes:
    """CDR bytes of an unorganised PointCloud2 with float32 x, y, z, intensity (and time).

    ``points_xyzi``: (N, 4) float32 in the sensor frame [m] and intensity (any unit);
    ``time_s``: (N,) per-point time [s] relative to ``stamp_ns``, or None.
    """
    pts = np.ascontiguousarray(points_xyzi, dtype="<f4")
    if pts.ndim != 2 or pts.shape[1] != 4:
        raise InputError(f"points must be (N, 4) x, y, z, intensity, got shape {pts.shape}")
    fields = list(XYZI_FIELDS)
    if time_s is not None:
        if np.shape(time_s) != (len(pts),):
            raise InputError(f"time_s must be ({len(pts)},), got shape {np.shape(time_s)}")
        pts = np.concatenate([pts, np.asarray(time_s, "<f4")[:, None]], axis=1)
        fields.append(TIME_FIELD)
    step = 4 * pts.shape[1]
    return encode(POINTCLOUD2, {
        "header": header(stamp_ns, frame_id),
        "height": 1, "width": len(pts),
        "fields": [vars(f) for f in fields],
        "is_bigendian": False, "point_step": step, "row_step": step * len(pts),
        "data": pts.tobytes(), "is_dense": True,
    })


def decode_pointcloud2(buf: bytes | memoryview, what: str = "PointCloud2") -> Any:
    """The decoded sensor_msgs/msg/PointCloud2 (``header``, ``fields``, ``data`` bytes, ...)."""
    return decode(POINTCLOUD2, buf, what)


def _layout(msg: Any) -> tuple[int, int, list[Any], bool, int, int, Any]:
    return (int(msg.height), int(msg.width), list(msg.fields), bool(msg.is_bigendian),
            int(msg.point_step), int(msg.row_step), msg.data)


def cloud_to_xyzi(msg: Any, what: str) -> NDArray[np.float32]:
    """(N, 4) float32 x, y, z, intensity of a decoded PointCloud2 (any layout; a message as
    mcap_ros2 or rosbags deserialises it, ROS 1 or ROS 2)."""
    return pointcloud2_to_xyzi(*_layout(msg), what)


def cloud_field(msg: Any, names: tuple[str, ...], what: str) -> tuple[str, NDArray] | None:
    """(name, (N,) values in the field's own dtype) of the first of ``names`` the decoded
    PointCloud2 has, or None."""
    height, width, fields, big, step, row_step, data = _layout(msg)
    by_name = {f.name: f for f in fields}
    name = next((n for n in names if n in by_name), None)
    if name is None:
        return None
    rows = _rows(height, width, step, row_step, data, what)
    return name, _column(rows, by_name[name], big, step, what)


def _rows(height: int, width: int, point_step: int, row_step: int,
          data: bytes | memoryview | NDArray[np.uint8], what: str) -> NDArray[np.uint8]:
    """(N, point_step) bytes of the points, rows padding removed; InputError on a bad size."""
    n = int(height) * int(width)
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    needed = row_step * (height - 1) + width * point_step if n else 0
    if point_step <= 0 or row_step < width * point_step or buf.size < needed:
        raise InputError(f"{what}: PointCloud2 data is {buf.size} bytes, expected {needed} "
                         f"({height}x{width} points, point_step {point_step}, row_step {row_step})")
    if row_step == width * point_step:  # rows without padding (a dense cloud): a view
        return buf[: n * point_step].reshape(n, point_step)
    padded = np.zeros(row_step * height, dtype=np.uint8)
    padded[: min(buf.size, padded.size)] = buf[: padded.size]
    return padded.reshape(height, row_step)[:, : width * point_step].reshape(n, point_step)


def _column(rows: NDArray[np.uint8], f: Any, big: bool, point_step: int, what: str) -> NDArray:
    """(N,) values of the PointField ``f`` (its first element) from ``rows``."""
    dt = POINTFIELD_DTYPES.get(int(f.datatype))
    if dt is None:
        raise InputError(f"{what}: field {f.name!r} has unknown datatype {f.datatype}")
    if f.offset + dt.itemsize > point_step:
        raise InputError(f"{what}: field {f.name!r} at offset {f.offset} overruns "
                         f"point_step {point_step}")
    raw = rows[:, f.offset : f.offset + dt.itemsize].copy()
    return raw.view(dt.newbyteorder(">" if big else "<"))[:, 0]


def pointcloud2_to_xyzi(
    height: int, width: int, fields: tuple[PointField, ...] | list, is_bigendian: bool,
    point_step: int, row_step: int, data: bytes | memoryview | NDArray[np.uint8], what: str,
) -> NDArray[np.float32]:
    """(N, 4) float32 x, y, z, intensity from any PointCloud2 layout.

    x, y, z must be float32 or float64; intensity (or ``reflectance``/``i``) is optional
    (zeros when absent), of any datatype. Raises InputError naming ``what`` for an unknown
    layout.
    """
    by_name = {f.name: f for f in fields}
    missing = [a for a in ("x", "y", "z") if a not in by_name]
    if missing:
        raise InputError(f"{what}: PointCloud2 has no field {', '.join(missing)} "
                         f"(fields: {', '.join(by_name) or 'none'})")
    for a in ("x", "y", "z"):
        if int(by_name[a].datatype) not in (7, 8):
            raise InputError(f"{what}: unsupported PointField layout: field {a!r} has datatype "
                             f"{by_name[a].datatype} (x, y, z must be FLOAT32=7 or FLOAT64=8)")
    n = int(height) * int(width)
    inten = next((k for k in ("intensity", "reflectance", "i") if k in by_name), None)
    if _packed_xyzi_float32(by_name, inten, is_bigendian, point_step, row_step, width):
        buf = np.frombuffer(bytes(data), np.uint8)
        if buf.size < point_step * n:
            raise InputError(f"{what}: PointCloud2 data is {buf.size} bytes, expected "
                             f"{point_step * n}")
        flat = np.frombuffer(buf, "<f4", count=n * point_step // 4)
        return flat.reshape(n, point_step // 4)[:, :4].copy()  # the common case: one copy
    rows = _rows(height, width, point_step, row_step, data, what)
    out = np.zeros((n, 4), dtype=np.float32)
    for col, name in enumerate(("x", "y", "z", inten)):
        if name is not None:
            out[:, col] = _column(rows, by_name[name], is_bigendian, point_step, what)
    return out


def _packed_xyzi_float32(by_name: dict[str, Any], inten: str | None, is_bigendian: bool,
                         point_step: int, row_step: int, width: int) -> bool:
    """True for the layouts adaptune writes (and most drivers): little-endian float32 x, y, z,
    intensity at offsets 0, 4, 8, 12, a point a whole number of floats, rows without padding."""
    if is_bigendian or inten is None or point_step < 16 or point_step % 4 or \
            row_step != point_step * width:
        return False
    return all(by_name[name].offset == 4 * k and by_name[name].datatype == 7
               and by_name[name].count == 1 for k, name in enumerate(("x", "y", "z", inten)))


def pose_dict(T_a_b: NDArray[np.float64]) -> dict[str, dict[str, float]]:
    """geometry_msgs/Pose fields (``position``, ``orientation``) of a (4, 4) transform."""
    from pipeline.geometry import rot_to_quat

    x, y, z = (float(v) for v in T_a_b[:3, 3])
    qx, qy, qz, qw = (float(v) for v in rot_to_quat(T_a_b[:3, :3]))
    return {"position": {"x": x, "y": y, "z": z},
            "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}


def pose_matrix(position: Any, orientation: Any, what: str) -> NDArray[np.float64]:
    """(4, 4) transform of a Point/Vector3 ``position`` and a Quaternion ``orientation``;
    InputError naming ``what`` when the quaternion is not a unit one (zero included)."""
    from pipeline.geometry import poses_from_quaternions

    return poses_from_quaternions(
        np.array([[position.x, position.y, position.z]], np.float64),
        np.array([[orientation.x, orientation.y, orientation.z, orientation.w]], np.float64),
        what,
    )[0]


def encode_pose_stamped(
    stamp_ns: int, T_world_x: NDArray[np.float64], frame_id: str = "world"
) -> bytes:
    """CDR bytes of a geometry_msgs/msg/PoseStamped from a (4, 4) pose."""
    return encode(POSE_STAMPED, {"header": header(stamp_ns, frame_id),
                                 "pose": pose_dict(T_world_x)})


def encode_path(stamps_ns: NDArray[np.int64], T_world_x: NDArray[np.float64],
                frame_id: str = "world") -> bytes:
    """CDR bytes of a nav_msgs/msg/Path of the poses ``T_world_x`` (N, 4, 4) at ``stamps_ns``
    (N,) [ns] (N >= 1), stamped with the last."""
    poses = [{"header": header(int(t), frame_id), "pose": pose_dict(T)}
             for t, T in zip(stamps_ns, T_world_x, strict=True)]
    return encode(PATH, {"header": header(int(stamps_ns[-1]), frame_id), "poses": poses})


def decode_pose_stamped(
    buf: bytes | memoryview, what: str = "PoseStamped"
) -> tuple[int, NDArray[np.float64]]:
    """(stamp_ns, (4, 4) pose) from CDR bytes of a geometry_msgs/msg/PoseStamped."""
    msg = decode(POSE_STAMPED, buf, what)
    return header_stamp_ns(msg), pose_matrix(msg.pose.position, msg.pose.orientation, what)


def encode_tf(stamp_ns: int, parent: str, child: str, T_parent_child: NDArray[np.float64]) -> bytes:
    """CDR bytes of a tf2_msgs/msg/TFMessage with one transform ``parent`` -> ``child``.

    ``T_parent_child``: (4, 4), maps points of ``child`` into ``parent`` (ROS convention:
    header.frame_id = parent, child_frame_id = child).
    """
    pose = pose_dict(T_parent_child)
    return encode(TF_MESSAGE, {"transforms": [{
        "header": header(stamp_ns, parent), "child_frame_id": child,
        "transform": {"translation": pose["position"], "rotation": pose["orientation"]},
    }]})


def decode_tf(
    buf: bytes | memoryview, what: str = "TFMessage"
) -> list[tuple[int, str, str, NDArray[np.float64]]]:
    """(stamp_ns, parent, child, (4, 4) T_parent_child) of every transform of a TFMessage."""
    msg = decode(TF_MESSAGE, buf, what)
    return [(header_stamp_ns(t), str(t.header.frame_id), str(t.child_frame_id),
             pose_matrix(t.transform.translation, t.transform.rotation, what))
            for t in msg.transforms]
