"""Real vehicle motion from a KITTI odometry ground-truth file, as T_world_lidar.

KITTI poses are camera-0 poses P_k (3x4, row-major, world = camera 0 of frame 0). With Tr the
velodyne -> camera-0 calibration, T_world_lidar_k = inv(Tr) P_k Tr (world = lidar of frame 0).
Tr comes from a ``calib.txt`` next to the file or, for files named ``NN.txt`` (sequences
00-10), from the benchmark's calibrations (``pipeline.kitti_calib.calib_for_pose_file``).
Stamps come from ``NN_times.txt`` next to the file when present, else 10 Hz.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3
from pipeline.io_utils import read_input_text
from pipeline.kitti_calib import calib_for_pose_file

F64 = NDArray[np.float64]


def kitti_lidar_poses(path: str | Path, frames: int | None = None) -> tuple[F64, NDArray[np.int64]]:
    """(T_world_lidar (N, 4, 4), stamps_ns (N,)) of the first ``frames`` poses of ``path``."""
    path = Path(path)
    text = read_input_text(path, "KITTI trajectory file")
    try:
        rows = np.loadtxt(io.StringIO(text), dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise InputError(f"{path}: not a KITTI pose file ({exc})") from None
    if rows.shape[1] != 12 or len(rows) < 2 or not np.isfinite(rows).all():
        raise InputError(f"{path}: expected lines of 12 finite numbers, got shape {rows.shape}")
    if frames is not None:
        if frames > len(rows):
            raise InputError(f"{path}: has {len(rows)} poses, {frames} frames requested")
        rows = rows[:frames]
    Tr = calib_for_pose_file(path)
    P = np.tile(np.eye(4), (len(rows), 1, 1))
    P[:, :3, :4] = rows.reshape(-1, 3, 4)
    T = inv_se3(Tr) @ P @ Tr
    times = path.with_name(path.stem + "_times.txt")
    if os.path.lexists(times):
        t = np.loadtxt(io.StringIO(read_input_text(times, "times file")), dtype=np.float64,
                       ndmin=1)[: len(rows)]
        stamps = 1_000_000_000 + np.round(t * 1e9).astype(np.int64)
        if len(stamps) == len(rows) and np.all(np.diff(stamps) > 0):
            return T, stamps
    return T, 1_000_000_000 + np.arange(len(rows), dtype=np.int64) * 100_000_000
