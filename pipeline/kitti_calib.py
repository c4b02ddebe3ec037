"""KITTI's LiDAR-camera calibration: ``Tr`` (velodyne -> camera 0) as a (4, 4) matrix.

KITTI's ground-truth poses are camera-0 poses P_k; with Tr, T_world_lidar_k = inv(Tr) P_k Tr
(world = lidar of frame 0). Tr comes from a sequence's ``calib.txt`` (line ``Tr:`` or
``Tr_velo_to_cam:``) or, for the ground-truth files ``00.txt`` .. ``10.txt`` of the odometry
benchmark, from the calibrations the benchmark publishes (``KITTI_TR``).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import refuse_non_rotations
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
"""Tr of the odometry benchmark's sequences 00-10 (12 numbers, row-major 3x4)."""

_TR_LINE = re.compile(r"^\s*(Tr|Tr_velo_to_cam)\s*:", re.MULTILINE)


def _as4x4(numbers: F64) -> F64:
    T = np.eye(4)
    T[:3, :4] = numbers.reshape(3, 4)
    return T


def read_kitti_calib(path: str | Path) -> F64:
    """(4, 4) Tr (velodyne -> camera 0) from a KITTI odometry calib.txt; InputError naming the
    file and its line when Tr is not 12 finite numbers of a rigid transform."""
    path = Path(path)
    for k, line in enumerate(read_input_text(path, "calibration file").splitlines(), 1):
        key, _, rest = line.partition(":")
        if key.strip() in ("Tr", "Tr_velo_to_cam"):
            try:
                vals = [float(v) for v in rest.split()]
            except ValueError:
                vals = []
            if len(vals) != 12 or not np.isfinite(vals).all():
                raise InputError(f"{path}: Tr must be 12 finite numbers, got {rest.strip()[:60]!r}")
            Tr = _as4x4(np.asarray(vals, np.float64))
            refuse_non_rotations(Tr[None, :3, :3], f"{path}: Tr", [k])
            return Tr
    raise InputError(f"{path}: no 'Tr' (velodyne -> camera) line in the calibration file")


def has_kitti_calib(text: str) -> bool:
    """True when ``text`` holds a KITTI ``Tr`` line (a calib.txt, not a list of numbers)."""
    return _TR_LINE.search(text) is not None


def calib_for_pose_file(path: Path) -> F64:
    """Tr (4, 4) for the KITTI ground-truth file ``path``: the ``calib.txt`` beside it when that
    has a Tr line, else the benchmark's for a file named ``00.txt`` .. ``10.txt``; InputError
    when neither is there."""
    calib = path.parent / "calib.txt"
    if os.path.lexists(calib) and has_kitti_calib(read_input_text(calib, "calibration file")):
        return read_kitti_calib(calib)
    m = re.fullmatch(r"(\d\d)\.txt", path.name)
    if m and int(m.group(1)) in KITTI_TR:
        return _as4x4(np.array(KITTI_TR[int(m.group(1))].split(), np.float64))
    raise InputError(
        f"{path}: no calib.txt with Tr beside it and not a KITTI sequence name "
        "00.txt .. 10.txt; cannot place the lidar"
    )
