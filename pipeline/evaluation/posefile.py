"""Pose text files: KITTI (12 numbers a line, row-major 3x4) and TUM (stamp tx ty tz qx qy qz qw).

The readers return (N, 4, 4) float64 poses; which frame they are in (camera or LiDAR) is the
caller's business. Errors name the file and the line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import pose_from_xyz_quat, rot_to_quat
from pipeline.io_utils import atomic_write_text

F64 = NDArray[np.float64]


def read_kitti_poses(path: str | Path) -> F64:
    """(N, 4, 4) poses of a KITTI pose file; InputError on a bad line or a non-finite pose."""
    rows = _read_rows(path, 12, "KITTI pose file (12 numbers a line)")
    T = np.zeros((len(rows), 4, 4))
    T[:, :3, :] = rows.reshape(-1, 3, 4)
    T[:, 3, 3] = 1.0
    return T


def write_kitti_poses(path: str | Path, poses: F64) -> None:
    """Write (N, 4, 4) poses as a KITTI pose file, atomically (%.12e, full precision)."""
    flat = np.asarray(poses, dtype=np.float64)[:, :3, :].reshape(-1, 12)
    lines = [" ".join(f"{v:.12e}" for v in row) for row in flat]
    atomic_write_text(path, "\n".join(lines) + ("\n" if lines else ""))


def read_tum(path: str | Path) -> tuple[F64, F64]:
    """(stamps_s (N,), poses (N, 4, 4)) of a TUM file (``#`` comments allowed)."""
    rows = _read_rows(path, 8, "TUM file (stamp tx ty tz qx qy qz qw)")
    return rows[:, 0].copy(), pose_from_xyz_quat(rows[:, 1:4], rows[:, 4:8])


def write_tum(path: str | Path, stamps_s: F64, poses: F64) -> None:
    """Write a TUM trajectory file, atomically: ``stamp tx ty tz qx qy qz qw`` per line."""
    poses = np.asarray(poses, dtype=np.float64)
    stamps_s = np.asarray(stamps_s, dtype=np.float64)
    if stamps_s.shape != (len(poses),):
        raise InputError(f"{path}: {len(stamps_s)} stamps for {len(poses)} poses")
    q = rot_to_quat(poses[:, :3, :3])
    t = poses[:, :3, 3]
    lines = [f"{s:.9f} " + " ".join(f"{v:.12e}" for v in (*ti, *qi))
             for s, ti, qi in zip(stamps_s, t, q, strict=True)]
    atomic_write_text(path, "\n".join(lines) + ("\n" if lines else ""))


def _read_rows(path: str | Path, width: int, what: str) -> F64:
    """(N, width) float64 rows of a whitespace-separated text file; InputError names the line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise InputError(f"{path}:{lineno}: not a number in {what}") from None
        if len(values) != width:
            raise InputError(f"{path}:{lineno}: {len(values)} numbers, expected {width} ({what})")
        if not np.isfinite(values).all():
            raise InputError(f"{path}:{lineno}: non-finite pose")
        rows.append(values)
    if not rows:
        raise InputError(f"{path}: no poses")
    return np.asarray(rows, dtype=np.float64)


EXPORT_FORMATS = ("kitti", "tum")


def export_trajectory(traj_path: str | Path, fmt: str, out: str | Path) -> int:
    """Write a trajectory Parquet file as KITTI or TUM text (poses as stored: T_world_lidar).

    Returns the number of poses written. TUM stamps are stamp_ns / 1e9 [s].
    """
    from pipeline.trajectory import read_trajectory

    if fmt not in EXPORT_FORMATS:
        raise InputError(f"unknown export format '{fmt}', known: {list(EXPORT_FORMATS)}")
    traj = read_trajectory(traj_path)
    if not traj.is_finite():
        raise InputError(f"{traj_path}: trajectory has non-finite poses")
    if fmt == "kitti":
        write_kitti_poses(out, traj.T_world_lidar)
    else:
        write_tum(out, traj.stamps_ns.astype(np.float64) / 1e9, traj.T_world_lidar)
    return len(traj)
