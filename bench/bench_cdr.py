"""ROS 2 CDR codecs of the sequence MCAP: mcap_ros2 (what pipeline/ros2_cdr.py uses) against
the hand-written struct codec it replaced (bench/reference/cdr_reference.py), in the same run.

Real KITTI scans of sequence 04: a 57,000-point cloud (the first points of a scan) and a full
scan (~123k points), encoded as sensor_msgs/msg/PointCloud2 and decoded back. Both codecs
must produce byte-identical messages (checked before timing).
"""

from __future__ import annotations

import numpy as np
from common import Row, best_of, data_root
from reference import cdr_reference as hand

STAMP_NS = 1_317_000_000_123_456_789


def run() -> list[Row]:
    from pipeline import ros2_cdr

    scan = data_root() / "kitti_mini" / "dataset" / "sequences" / "04" / "velodyne" / "000000.bin"
    full = np.fromfile(scan, np.float32).reshape(-1, 4)
    rows: list[Row] = []
    for pts in (full[:57_000], full):
        n = len(pts)
        lib = ros2_cdr.encode_pointcloud2(STAMP_NS, pts)
        assert lib == hand.encode_pointcloud2(STAMP_NS, pts), "encoders disagree"
        got = ros2_cdr.decode_pointcloud2(lib)
        assert got.data == hand.decode_pointcloud2(lib).data, "decoders disagree"

        def enc_lib(p: np.ndarray = pts) -> bytes:
            return ros2_cdr.encode_pointcloud2(STAMP_NS, p)

        def enc_hand(p: np.ndarray = pts) -> bytes:
            return hand.encode_pointcloud2(STAMP_NS, p)

        t_lib, t_hand = best_of(enc_lib, 7, 20), best_of(enc_hand, 7, 20)
        rows.append(Row(f"PointCloud2 encode, {n} points (mcap_ros2)", 1e3 * t_lib, "ms",
                        f"hand-written: {1e3 * t_hand:.3f} ms (byte-identical)",
                        "library unless a real difference"))
        t_lib = best_of(lambda b=lib: ros2_cdr.decode_pointcloud2(b), 7, 20)
        t_hand = best_of(lambda b=lib: hand.decode_pointcloud2(b), 7, 20)
        rows.append(Row(f"PointCloud2 decode, {n} points (mcap_ros2)", 1e3 * t_lib, "ms",
                        f"hand-written: {1e3 * t_hand:.3f} ms", ""))
    return rows
