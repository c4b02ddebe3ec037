"""Real vehicle motion from a KITTI odometry ground-truth file, as T_world_lidar.

KITTI poses are camera-0 poses P_k (3x4, row-major, world = camera 0 of frame 0). With Tr the
velodyne -> camera-0 calibration, T_world_lidar_k = inv(Tr) P_k Tr (world = lidar of frame 0).
Tr comes from a ``calib.txt`` next to the file (line ``Tr:``) or, for files named ``NN.txt``
(sequences 00-10), from the calibrations listed in ../shared/data/kitti_trajectories/README.md.
Stamps come from ``NN_times.txt`` next to the file when present, else 10 Hz.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3
from pipeline.io_utils import read_input_text

F64 = NDArray[np.float64]

_TR_00_02 = (
    "4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 "
    "-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 "
    "9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01"
)
_TR_03 = (
    "2.347736981471e-04 -9.999441545438e-01 -1.056347781105e-02 -2.796816941295e-03 "
    "1.044940741659e-02 1.056535364138e-02 -9.998895741176e-01 -7.510879138296e-02 "
    "9.999453885620e-01 1.243653783865e-04 1.045130299567e-02 -2.721327964059e-01"
)
_TR_04_10 = (
    "-1.857739385241e-03 -9.999659513510e-01 -8.039975204516e-03 -4.784029760483e-03 "
    "-6.481465826011e-03 8.051860151134e-03 -9.999466081774e-01 -7.337429464231e-02 "
    "9.999773098287e-01 -1.805528627661e-03 -6.496203536139e-03 -3.339968064433e-01"
)
KITTI_TR = {i: (_TR_00_02 if i <= 2 else _TR_03 if i == 3 else _TR_04_10) for i in range(11)}


def _as4x4(numbers: F64) -> F64:
    T = np.eye(4)
    T[:3, :4] = numbers.reshape(3, 4)
    return T


def velodyne_to_camera(path: Path) -> F64:
    """Tr (4, 4) for the KITTI pose file ``path``; InputError when it cannot be found."""
    calib = path.parent / "calib.txt"
    if os.path.lexists(calib):
        for line in read_input_text(calib, "calibration file").splitlines():
            if line.startswith("Tr:"):
                return _as4x4(np.array(line.split()[1:], np.float64))
    m = re.fullmatch(r"(\d\d)\.txt", path.name)
    if m and int(m.group(1)) in KITTI_TR:
        return _as4x4(np.array(KITTI_TR[int(m.group(1))].split(), np.float64))
    raise InputError(
        f"{path}: no calib.txt with Tr beside it and not a KITTI sequence name "
        "00.txt .. 10.txt; cannot place the lidar"
    )


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
    Tr = velodyne_to_camera(path)
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
