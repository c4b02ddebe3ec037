"""Ground-truth pose files and time matching.

- KITTI pose file: one pose a line, 12 numbers (row-major 3x4), no time; line k = frame k.
- TUM pose file: ``stamp_s tx ty tz qx qy qz qw`` a line, ``#`` comments; matched by time.
- KITTI calib.txt: ``Tr`` (velodyne -> camera 0, 3x4); T_world_lidar = inv(Tr) @ P @ Tr.
Stamped poses (TUM, or pose / odometry / TF topics) are interpolated to the scan stamps
(linear in translation, slerp in rotation); a scan outside the poses' time span is an error.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import interpolate_rotations, inv_se3, pose_from_xyz_quat

PoseFormat = Literal["kitti", "tum", "auto"]
MATCH_TOLERANCE_NS = 10_000_000
"""A scan up to 10 ms outside the poses' time span takes the nearest end pose."""
MAX_GAP_NS = 1_000_000_000
"""Two poses further apart than 1 s are not interpolated between."""


@dataclass(frozen=True)
class PoseFile:
    """Poses read from a file: (M, 4, 4) ``T_world_x``, ``stamps_ns`` (M,) or None (KITTI)."""

    path: Path
    format: str
    T_world_x: NDArray[np.float64]
    stamps_ns: NDArray[np.int64] | None


def _numbers(path: Path) -> list[tuple[int, list[float], str]]:
    """(line number, values, first token) of the non-empty, non-comment lines of a text file."""
    if not path.is_file():
        raise InputError(f"{path}: no such pose file")
    rows = []
    for k, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        text = line.split("#", 1)[0].replace(",", " ").strip()
        if not text:
            continue
        try:
            rows.append((k, [float(v) for v in text.split()], text.split()[0]))
        except ValueError:
            raise InputError(
                f"{path} line {k}: not a list of numbers: {line.strip()[:60]!r}"
            ) from None
    if not rows:
        raise InputError(f"{path}: no poses in the file")
    return rows


def read_pose_file(path: str | Path, fmt: PoseFormat = "auto") -> PoseFile:
    """Read a KITTI (12 numbers a line) or TUM (8 numbers a line) pose file."""
    path = Path(path)
    rows = _numbers(path)
    kind = {12: "kitti", 8: "tum"}.get(len(rows[0][1]), "kitti") if fmt == "auto" else fmt
    width = 12 if kind == "kitti" else 8
    for k, vals, _ in rows:
        if len(vals) != width:
            raise InputError(
                f"{path} line {k}: expected {width} numbers ({kind} pose file), got {len(vals)}"
            )
    arr = np.array([v for _, v, _ in rows], dtype=np.float64)
    if not np.isfinite(arr).all():
        k = rows[int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])][0]
        raise InputError(f"{path} line {k}: pose is not finite")
    if kind == "kitti":
        T = np.tile(np.eye(4), (len(arr), 1, 1))
        T[:, :3, :] = arr.reshape(-1, 3, 4)
        return PoseFile(path, kind, T, None)
    stamps = np.array([_seconds_to_ns(tok) for _, _, tok in rows], np.int64)
    if np.any(np.diff(stamps) <= 0):
        raise InputError(f"{path}: TUM stamps are not strictly increasing")
    return PoseFile(path, kind, pose_from_xyz_quat(arr[:, 1:4], arr[:, 4:8]), stamps)


def _seconds_to_ns(token: str) -> int:
    """Exact ns of a decimal seconds string (a float64 would lose ~200 ns at epoch times)."""
    return int((Decimal(token) * 1_000_000_000).to_integral_value())


def read_kitti_calib(path: str | Path) -> NDArray[np.float64]:
    """(4, 4) Tr (velodyne -> camera 0) from a KITTI odometry calib.txt."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such calibration file")
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        key, _, rest = line.partition(":")
        if key.strip() in ("Tr", "Tr_velo_to_cam"):
            try:
                vals = [float(v) for v in rest.split()]
            except ValueError:
                vals = []
            if len(vals) != 12 or not np.isfinite(vals).all():
                raise InputError(f"{path}: Tr must be 12 finite numbers, got {rest.strip()[:60]!r}")
            Tr = np.eye(4)
            Tr[:3, :] = np.reshape(vals, (3, 4))
            return Tr
    raise InputError(f"{path}: no 'Tr' (velodyne -> camera) line in the calibration file")


def camera_to_lidar(
    T_world_cam: NDArray[np.float64], Tr: NDArray[np.float64]
) -> NDArray[np.float64]:
    """KITTI ground truth in the lidar frame: inv(Tr) @ P @ Tr for (..., 4, 4) camera poses P."""
    return inv_se3(Tr) @ T_world_cam @ Tr


def check_count(poses: PoseFile, n_scans: int, scans_what: str) -> None:
    """A pose file without stamps must hold exactly one pose per scan."""
    if len(poses.T_world_x) != n_scans:
        raise InputError(
            f"{poses.path}: {len(poses.T_world_x)} poses for {n_scans} scans in {scans_what}"
        )


def interpolate_poses(
    query_ns: NDArray[np.int64],
    stamps_ns: NDArray[np.int64],
    T_world_x: NDArray[np.float64],
    what: str,
) -> NDArray[np.float64]:
    """(Q, 4, 4) poses at ``query_ns`` from stamped poses (M, 4, 4) (sorted by ``stamps_ns``).

    Linear in translation, slerp in rotation; exact where a stamp matches. Raises InputError
    (naming ``what``) for a query outside the span (beyond MATCH_TOLERANCE_NS) or between
    two poses more than MAX_GAP_NS apart.
    """
    order = np.argsort(stamps_ns, kind="stable")
    t = np.asarray(stamps_ns, np.int64)[order]
    T = np.asarray(T_world_x, np.float64)[order]
    q = np.asarray(query_ns, np.int64)
    outside = (q < t[0] - MATCH_TOLERANCE_NS) | (q > t[-1] + MATCH_TOLERANCE_NS)
    if outside.any():
        which = (
            f"the scan at {q[0] / 1e9:.3f} s lies"
            if len(q) == 1
            else f"{int(outside.sum())} of {len(q)} scans (first at "
            f"{q[outside][0] / 1e9:.3f} s) lie"
        )
        raise InputError(
            f"{what}: {which} outside the ground-truth time span "
            f"[{t[0] / 1e9:.3f}, {t[-1] / 1e9:.3f}] s"
        )
    qc = np.clip(q, t[0], t[-1])
    hi = np.clip(np.searchsorted(t, qc, side="left"), 0, len(t) - 1)
    lo = np.clip(hi - 1, 0, len(t) - 1)
    exact = t[hi] == qc
    lo = np.where(exact, hi, lo)
    gap = t[hi] - t[lo]
    if np.any(gap > MAX_GAP_NS):
        k = int(np.flatnonzero(gap > MAX_GAP_NS)[0])
        raise InputError(
            f"{what}: no ground-truth pose within {MAX_GAP_NS / 1e9:g} s around "
            f"the scan at {q[k] / 1e9:.3f} s"
        )
    alpha = np.where(gap > 0, (qc - t[lo]) / np.maximum(gap, 1), 0.0)
    out = np.tile(np.eye(4), (len(q), 1, 1))
    out[:, :3, 3] = (1 - alpha)[:, None] * T[lo, :3, 3] + alpha[:, None] * T[hi, :3, 3]
    out[:, :3, :3] = interpolate_rotations(
        (qc - t[0]).astype(np.float64), (t - t[0]).astype(np.float64), T[:, :3, :3]
    )
    out[exact] = T[hi[exact]]
    return out


def ground_truth_for(
    stamps_ns: list[int] | NDArray[np.int64],
    poses: PoseFile,
    scans_what: str,
    Tr: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """(N, 4, 4) T_world_lidar of the scans at ``stamps_ns`` from a pose file.

    KITTI files: line k is scan k (the counts must match). TUM files: matched by time.
    ``Tr`` (4, 4), when given, turns camera poses into lidar poses (inv(Tr) @ P @ Tr).
    """
    if poses.stamps_ns is None:
        check_count(poses, len(stamps_ns), scans_what)
        T = poses.T_world_x
    else:
        T = interpolate_poses(
            np.asarray(stamps_ns, np.int64), poses.stamps_ns, poses.T_world_x, str(poses.path)
        )
    return camera_to_lidar(T, Tr) if Tr is not None else T
