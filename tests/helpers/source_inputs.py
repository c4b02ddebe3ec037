"""Inputs for the ingest tests, built from real KITTI scans with each format's own writer.

Nothing here uses adaptune's readers: KITTI is read with numpy, bags are written with
rosbags' rosbag1 / rosbag2 writers and typestore serialisation, PCD files by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import rot_to_quat

BAG_T0_NS = 1_700_000_000_000_000_000  # bags carry epoch stamps; KITTI times start at 0


@dataclass
class KittiFrames:
    """The first frames of a KITTI sequence, read independently of adaptune."""

    bins: list[Path]
    stamps_ns: NDArray[np.int64]
    points: list[NDArray[np.float32]]
    T_world_cam: NDArray[np.float64]
    Tr: NDArray[np.float64]

    @property
    def T_world_lidar(self) -> NDArray[np.float64]:
        return np.linalg.inv(self.Tr) @ self.T_world_cam @ self.Tr


def load_kitti(root: Path, seq: str, n: int | None = None) -> KittiFrames:
    d = root / "sequences" / seq
    bins = sorted((d / "velodyne").glob("*.bin"))[:n]
    times = np.loadtxt(d / "times.txt")[: len(bins)]
    calib = {
        k: v for k, _, v in (ln.partition(":") for ln in (d / "calib.txt").read_text().splitlines())
    }
    Tr = np.vstack([np.array(calib["Tr"].split(), float).reshape(3, 4), [0, 0, 0, 1]])
    P = np.loadtxt(root / "poses" / f"{seq}.txt")[: len(bins)].reshape(-1, 3, 4)
    T_world_cam = np.concatenate([P, np.tile([[[0, 0, 0, 1.0]]], (len(P), 1, 1))], axis=1)
    points = [np.fromfile(b, np.float32).reshape(-1, 4) for b in bins]
    return KittiFrames(bins, np.round(times * 1e9).astype(np.int64), points, T_world_cam, Tr)


# ---------------------------------------------------------------- ROS messages (rosbags)


def typestore(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.fielddefs:
        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    return ts


def header(ts: Any, stamp_ns: int, frame_id: str, ros1: bool) -> Any:
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    if ros1:
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


LAYOUTS = {
    # name: [(field, datatype, offset)], point_step, numpy dtype of a point
    "xyzi32": ([("x", 7, 0), ("y", 7, 4), ("z", 7, 8), ("intensity", 7, 12)], 16),
    "xyzi64_ring": (
        [("x", 8, 0), ("y", 8, 8), ("z", 8, 16), ("intensity", 8, 24), ("ring", 4, 32)],
        40,
    ),
    "xyz64_i8_ring_time": (  # float64 x, y, z; uint8 intensity 0-255; uint16 ring; float32 time
        [("x", 8, 0), ("y", 8, 8), ("z", 8, 16), ("intensity", 2, 24), ("ring", 4, 26),
         ("time", 7, 28)],
        32,
    ),
    "x_int16": ([("x", 3, 0), ("y", 7, 4), ("z", 7, 8)], 12),
    "no_z": ([("x", 7, 0), ("y", 7, 4), ("intensity", 7, 8)], 12),
}


def point_times_s(points: NDArray[np.float32]) -> NDArray[np.float32]:
    """Per-point time [s] of a 10 Hz sweep starting at azimuth -pi: its azimuth's share."""
    az = np.arctan2(points[:, 1], points[:, 0]).astype(np.float64)
    return ((az + np.pi) / (2 * np.pi) * 0.1).astype(np.float32)


def cloud_bytes(points: NDArray[np.float32], layout: str, big: bool = False) -> bytes:
    """Point bytes of ``points`` (N, 4) in one of LAYOUTS (big-endian values when ``big``)."""
    fields, step = LAYOUTS[layout]
    buf = np.zeros((len(points), step), np.uint8)
    order = ">" if big else "<"
    codes = {7: order + "f4", 8: order + "f8", 2: "u1", 3: order + "i2", 4: order + "u2"}
    cols = {"x": 0, "y": 1, "z": 2, "intensity": 3}
    for name, dt, off in fields:
        if name == "time":  # a 10 Hz sweep: the azimuth's share of 0.1 s
            vals = point_times_s(points)
        elif name == "intensity" and dt == 2:  # 8-bit, as drivers give it
            vals = np.round(points[:, 3] * 255.0)
        else:
            vals = points[:, cols[name]] if name in cols else np.arange(len(points)) % 64
        raw = np.ascontiguousarray(vals.astype(codes[dt])).view(np.uint8).reshape(len(points), -1)
        buf[:, off : off + raw.shape[1]] = raw
    return buf.tobytes()


ORGANIZED = {"organized_be": (16, 24, True)}
"""Cloud shapes besides the flat little-endian one: name -> (height, row padding in bytes,
big-endian): an organized cloud (one row a beam, as Ouster drivers publish), each row padded."""


def cloud_msg(
    ts: Any, stamp_ns: int, points: NDArray[np.float32], ros1: bool, layout: str = "xyzi32",
    shape: str = "flat",
) -> Any:
    """A PointCloud2 of ``points`` in ``layout``; ``shape`` flat or one of ORGANIZED (then
    ``points`` must fill whole rows)."""
    T = ts.types
    fields, step = LAYOUTS[layout]
    height, pad, big = ORGANIZED.get(shape, (1, 0, False))
    width = len(points) // height
    assert width * height == len(points), "an organized cloud needs whole rows"
    pf = [
        T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=1) for n, d, o in fields
    ]
    rows = np.frombuffer(cloud_bytes(points, layout, big), np.uint8).reshape(height, -1)
    data = np.concatenate([rows, np.full((height, pad), 0xAB, np.uint8)], axis=1).ravel()
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(ts, stamp_ns, "velodyne", ros1),
        height=height,
        width=width,
        fields=pf,
        is_bigendian=big,
        point_step=step,
        row_step=step * width + pad,
        data=data,
        is_dense=False,
    )


def _pose_msg(ts: Any, T_w: NDArray[np.float64]) -> Any:
    T = ts.types
    q = rot_to_quat(T_w[:3, :3])
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=T_w[0, 3], y=T_w[1, 3], z=T_w[2, 3]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
    )


def _transform_stamped(
    ts: Any, stamp_ns: int, T_w: NDArray[np.float64], child: str, ros1: bool
) -> Any:
    T = ts.types
    q = rot_to_quat(T_w[:3, :3])
    tf = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=T_w[0, 3], y=T_w[1, 3], z=T_w[2, 3]),
        rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
    )
    return T["geometry_msgs/msg/TransformStamped"](
        header=header(ts, stamp_ns, "world", ros1), child_frame_id=child, transform=tf
    )


GT_TOPICS = {"pose": "/ground_truth", "posecov": "/pose_cov", "transform": "/transform",
             "odom": "/odom", "tf": "/tf"}
"""The topic write_bag gives each kind of ground truth."""


def gt_msg(
    ts: Any, kind: str, stamp_ns: int, T_w: NDArray[np.float64], ros1: bool
) -> tuple[str, Any]:
    """(msgtype, message) of a ground-truth pose: kind pose | posecov | transform | odom |
    tf (GT_TOPICS)."""
    T = ts.types
    if kind == "pose":
        return "geometry_msgs/msg/PoseStamped", T["geometry_msgs/msg/PoseStamped"](
            header=header(ts, stamp_ns, "world", ros1), pose=_pose_msg(ts, T_w)
        )
    if kind == "posecov":
        return ("geometry_msgs/msg/PoseWithCovarianceStamped",
                T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                    header=header(ts, stamp_ns, "world", ros1),
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](
                        pose=_pose_msg(ts, T_w), covariance=np.zeros(36))))
    if kind == "transform":
        return ("geometry_msgs/msg/TransformStamped",
                _transform_stamped(ts, stamp_ns, T_w, "velodyne", ros1))
    if kind == "odom":
        cov = np.zeros(36)
        return "nav_msgs/msg/Odometry", T["nav_msgs/msg/Odometry"](
            header=header(ts, stamp_ns, "world", ros1),
            child_frame_id="velodyne",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose_msg(ts, T_w), covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](
                    linear=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                    angular=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                ),
                covariance=cov,
            ),
        )
    decoy = T_w.copy()
    decoy[:3, 3] += 5.0  # another frame in the same TF message, that must not be taken
    return "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](
        transforms=[
            _transform_stamped(ts, stamp_ns, decoy, "base_link", ros1),
            _transform_stamped(ts, stamp_ns, T_w, "velodyne", ros1),
        ]
    )


def write_bag(
    path: Path,
    kf: KittiFrames,
    *,
    ros: int,
    storage: str = "sqlite3",
    gt: str | None = "pose",
    layout: str = "xyzi32",
    shape: str = "flat",
    cloud_topic: str = "/velodyne_points",
    extra_topics: tuple[str, ...] = (),
    more_gt: tuple[str, ...] = (),
) -> Path:
    """A real ROS 1 .bag (ros=1) or ROS 2 bag folder (ros=2, sqlite3 | mcap storage) of ``kf``.

    Scan k is at BAG_T0_NS + kf.stamps_ns[k]; ground truth (``gt``: a kind of GT_TOPICS, or
    None) at the same stamps. Clouds in ``layout`` (LAYOUTS) and ``shape`` (flat or one of
    ORGANIZED). ``extra_topics`` are more PointCloud2 topics (one message each); ``more_gt``
    more ground-truth kinds, each on its own topic as ``gt``.
    """
    ros1 = ros == 1
    ts = typestore(ros1)
    stamps = BAG_T0_NS + kf.stamps_ns
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(path)
        serialize = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
        serialize = ts.serialize_cdr
    with writer:
        pc2 = "sensor_msgs/msg/PointCloud2"
        conn = writer.add_connection(cloud_topic, pc2, typestore=ts)
        extra = [writer.add_connection(t, pc2, typestore=ts) for t in extra_topics]
        gt_conns = {}
        for kind in ([gt] if gt is not None else []) + list(more_gt):
            msgtype = gt_msg(ts, kind, 0, np.eye(4), ros1)[0]
            gt_conns[kind] = writer.add_connection(GT_TOPICS[kind], msgtype, typestore=ts)
        for k, pts in enumerate(kf.points):
            t = int(stamps[k])
            writer.write(conn, t, serialize(cloud_msg(ts, t, pts, ros1, layout, shape), pc2))
            for kind, gt_conn in gt_conns.items():
                msgtype, msg = gt_msg(ts, kind, t, kf.T_world_lidar[k], ros1)
                writer.write(gt_conn, t, serialize(msg, msgtype))
        for c in extra:
            t = int(stamps[0])
            writer.write(c, t, serialize(cloud_msg(ts, t, kf.points[0][:100], ros1), pc2))
    return path


# ---------------------------------------------------------------- scan files


def write_pcd(path: Path, points: NDArray[np.float32], ascii_data: bool = False) -> None:
    """A PCD v0.7 file with float32 x, y, z, intensity (binary or ascii), written by hand."""
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\n"
        "SIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\n"
        f"DATA {'ascii' if ascii_data else 'binary'}\n"
    )
    if ascii_data:
        body = "\n".join(" ".join(f"{v:.9g}" for v in row) for row in points).encode() + b"\n"
    else:
        body = np.ascontiguousarray(points, "<f4").tobytes()
    path.write_bytes(head.encode() + body)


def write_kitti_poses(path: Path, T: NDArray[np.float64]) -> None:
    path.write_text("\n".join(" ".join(f"{v:.12e}" for v in P[:3].ravel()) for P in T) + "\n")


def write_tum(path: Path, stamps_ns: NDArray[np.int64], T: NDArray[np.float64]) -> None:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for t, P in zip(stamps_ns, T, strict=True):
        q = rot_to_quat(P[:3, :3])
        lines.append(
            f"{t // 10**9}.{t % 10**9:09d} " + " ".join(f"{v:.15g}" for v in [*P[:3, 3], *q])
        )
    path.write_text("\n".join(lines) + "\n")
