"""ROS messages (as ``rosbags`` deserialises them, ROS 1 or ROS 2) -> points, stamps, poses.

Point clouds: sensor_msgs/PointCloud2 of any layout with float32/float64 x, y, z (intensity
optional), through pipeline.ros2_cdr.cloud_to_xyzi. Ground truth: geometry_msgs
PoseStamped / PoseWithCovarianceStamped / TransformStamped, nav_msgs/Odometry, and
tf2_msgs/TFMessage (the transform whose child frame is ``child_frame``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.ros2_cdr import cloud_field, cloud_to_xyzi, pose_matrix
from pipeline.sources.base import Frame
from pipeline.sources.pointtime import relative_times_s
from pipeline.sources.poses import GroundTruth
from pipeline.sources.scanfiles import TIME_NAMES

POINTCLOUD2_TYPES = ("sensor_msgs/msg/PointCloud2",)
POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
)
TF_TYPE = "tf2_msgs/msg/TFMessage"


def normalise_type(msgtype: str) -> str:
    """'sensor_msgs/PointCloud2' (ROS 1) -> 'sensor_msgs/msg/PointCloud2'."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def stamp_ns(msg: Any, fallback_ns: int) -> int:
    """The header stamp [ns] of a message; ``fallback_ns`` (the log time) when it is zero."""
    st = msg.header.stamp
    ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
    return ns if ns != 0 else int(fallback_ns)


def cloud_frame(msg: Any, log_ns: int, k: int, gt: GroundTruth | None, what: str) -> Frame:
    """The Frame of the k-th deserialised PointCloud2 ``msg``: header stamp (the log time
    where zero), x, y, z, intensity, per-point time (``t``, ``time``, ``timestamp`` or
    ``offset_time``) where the cloud has it, and the ground truth at the stamp."""
    stamp = stamp_ns(msg, log_ns)
    column = cloud_field(msg, TIME_NAMES, what)
    times = None if column is None else relative_times_s(column[1], column[0], stamp, what)
    return Frame(stamp, cloud_to_xyzi(msg, what), None if gt is None else gt.at(k, stamp),
                 what, times)


def _pose(p: Any, what: str) -> NDArray[np.float64]:
    return pose_matrix(p.position, p.orientation, what)


def _transform(t: Any, what: str) -> NDArray[np.float64]:
    return pose_matrix(t.translation, t.rotation, what)


def poses_of(
    msg: Any, msgtype: str, log_ns: int, child_frame: str | None, what: str
) -> list[tuple[int, NDArray[np.float64], str]]:
    """(stamp_ns, (4, 4) pose, child frame) entries of one ground-truth message.

    TF messages yield only transforms whose child frame is ``child_frame`` (all when None,
    so the caller can list what is there).
    """
    msgtype = normalise_type(msgtype)
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return [(stamp_ns(msg, log_ns), _pose(msg.pose, what), "")]
    if msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped":
        return [(stamp_ns(msg, log_ns), _pose(msg.pose.pose, what), "")]
    if msgtype == "nav_msgs/msg/Odometry":
        return [(stamp_ns(msg, log_ns), _pose(msg.pose.pose, what), str(msg.child_frame_id))]
    if msgtype == "geometry_msgs/msg/TransformStamped":
        return [(stamp_ns(msg, log_ns), _transform(msg.transform, what), str(msg.child_frame_id))]
    if msgtype == TF_TYPE:
        return [
            (stamp_ns(t, log_ns), _transform(t.transform, what), str(t.child_frame_id))
            for t in msg.transforms
            if child_frame is None or t.child_frame_id == child_frame
        ]
    raise InputError(f"{what}: {msgtype} is not a ground-truth type ({', '.join(POSE_TYPES)})")


def collect_poses(
    entries: list[tuple[int, NDArray[np.float64], str]],
    msgtype: str,
    child_frame: str | None,
    what: str,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Stamps (M,) and poses (M, 4, 4) sorted by time, from ``poses_of`` entries of a topic."""
    if normalise_type(msgtype) == TF_TYPE:
        frames = sorted({c for _, _, c in entries})
        if child_frame is None:
            raise InputError(
                f"{what}: a TF ground-truth topic needs a child frame "
                f"(--gt-child-frame; frames here: {', '.join(frames) or 'none'})"
            )
        entries = [e for e in entries if e[2] == child_frame]
        if not entries:
            raise InputError(
                f"{what}: no transform with child frame {child_frame!r} "
                f"(frames here: {', '.join(frames) or 'none'})"
            )
    if not entries:
        raise InputError(f"{what}: no ground-truth messages")
    entries = sorted(entries, key=lambda e: e[0])
    stamps = np.array([e[0] for e in entries], np.int64)
    keep = np.concatenate([[True], np.diff(stamps) > 0])  # duplicates: keep the first
    return stamps[keep], np.stack([e[1] for e in entries])[keep]
