"""Pose text files: every format evo reads, plus the 4x4 block, read into (M, 4, 4) poses.

- ``kitti``: 12 numbers a line, the row-major 3x4 [R | t]; no stamps (line k = frame k).
- ``tum``: ``stamp_s tx ty tz qx qy qz qw`` a line (``#`` comments).
- ``euroc``: the EuRoC / ASL CSV with a header: ``timestamp [ns], p x, y, z [m], q w, x, y, z``
  (w first), further columns ignored (``#timestamp,p_RS_R_x [m],...,q_RS_w [],...``).
- ``matrix4``: a 4x4 matrix a pose on 4 lines; element (3, 3) is 1, or the stamp [s] (as the
  LiDAR-inertial mapping tools write it).
``auto`` tells them apart by their content only where that is unambiguous (numbers a line,
commas and a header: ``fitting_formats``); otherwise it asks for the format, naming every one
that could fit. Rotations must be rotations (R^T R = I,
det +1) and quaternions unit ones. Which frame the poses are in (camera or LiDAR) is the
caller's business. Errors name the file and the line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import poses_from_quaternions, refuse_non_rotations, rot_to_quat
from pipeline.io_utils import atomic_write_text, read_input_text
from pipeline.stamps import check_stamp_ns, decimal_seconds_to_ns, seconds_to_ns

F64 = NDArray[np.float64]
PoseFormat = Literal["auto", "kitti", "tum", "euroc", "matrix4"]
POSE_FORMATS: tuple[str, ...] = ("auto", "kitti", "tum", "euroc", "matrix4")
_WIDTHS = {"kitti": 12, "tum": 8, "matrix4": 4}


@dataclass(frozen=True)
class PoseFile:
    """Poses read from a file: (M, 4, 4) ``T_world_x``; ``stamps_ns`` (M,) or None (KITTI,
    a 4x4 block without stamps: pose k is frame k)."""

    path: Path
    format: str
    T_world_x: F64
    stamps_ns: NDArray[np.int64] | None


@dataclass(frozen=True)
class _Rows:
    """The data lines of a pose file: line numbers, tokens (first kept as text for exact
    stamps), numbers, whether comma-separated, and the header / comment lines."""

    lines: list[int]
    tokens: list[list[str]]
    values: list[list[float]]
    commas: bool
    header: list[str]


def _rows(path: Path) -> _Rows:
    text = read_input_text(path, "pose file")
    lines: list[int] = []
    tokens: list[list[str]] = []
    values: list[list[float]] = []
    header: list[str] = []
    commas = False
    for k, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith(("#", "%", "//")) or re.match(r"[A-Za-z_]", stripped):
            if values:
                raise InputError(f"{path} line {k}: not a list of numbers: {stripped[:60]!r}")
            header.append(stripped)
            continue
        commas = commas or "," in stripped
        toks = [t for t in re.split(r"[,\s]+", stripped) if t]
        try:
            values.append([float(t) for t in toks])
        except ValueError:
            raise InputError(f"{path} line {k}: not a list of numbers: {stripped[:60]!r}") from None
        lines.append(k)
        tokens.append(toks)
    if not values:
        raise InputError(f"{path}: no poses in the file")
    return _Rows(lines, tokens, values, commas, header)


def fitting_formats(rows: _Rows) -> list[str]:
    """Every format whose shape the data has, by its first line (a later line of another width
    is then an error naming that line): ``kitti`` 12 numbers, ``tum`` 8, ``euroc`` 8 or more
    comma-separated, ``matrix4`` 4, in blocks of 4 lines whose last rows start 0 0 0."""
    width = len(rows.values[0])
    fits = []
    if width == 12:
        fits.append("kitti")
    if width == 8:
        fits.append("tum")
    if rows.commas and width >= 8:
        fits.append("euroc")
    if width == 4 and len(rows.values) % 4 == 0 and all(
            rows.values[i][:3] == [0.0, 0.0, 0.0] for i in range(3, len(rows.values), 4)):
        fits.append("matrix4")
    return fits


def guess_format(path: Path, rows: _Rows) -> str:
    """The format of a pose file from its content, where unambiguous (module docstring): the
    only format that fits (``fitting_formats``), EuRoC only with its header (a CSV of 8 numbers
    could be EuRoC, qw first, or TUM with commas, qw last). InputError naming every format
    that could fit otherwise."""
    fits = fitting_formats(rows)
    head = " ".join(rows.header).lower()
    if "euroc" in fits and ("q_rs_w" in head or head.startswith("#timestamp")):
        return "euroc"
    if len(fits) == 1 and fits != ["euroc"]:
        return fits[0]
    shape = f"{len(rows.values[0])} numbers a line" + (", comma-separated" if rows.commas
                                                        else "")
    if fits:
        no_header = " without an EuRoC header" if "euroc" in fits else ""
        return _refuse_format(path, f"{shape}{no_header} could be {' or '.join(fits)}; give "
                              f"--poses-format {'|'.join(fits)}")
    return _refuse_format(path, f"cannot tell the pose format from {shape} (kitti: 12, tum: 8, "
                          "matrix4: 4 lines of 4, euroc: CSV with a header); give "
                          "--poses-format")


def _refuse_format(path: Path, why: str) -> str:
    raise InputError(f"{path}: {why}")


def read_pose_file(path: str | Path, fmt: PoseFormat = "auto") -> PoseFile:
    """Read a pose file of format ``fmt`` (module docstring); InputError names the line."""
    path = Path(path)
    rows = _rows(path)
    kind = guess_format(path, rows) if fmt == "auto" else fmt
    if kind == "euroc":
        return _euroc(path, rows)
    width = _WIDTHS.get(kind)
    if width is None:
        raise InputError(f"unknown pose format {kind!r} (known: {', '.join(POSE_FORMATS)})")
    for k, vals in zip(rows.lines, rows.values, strict=True):
        if len(vals) != width:
            raise InputError(f"{path} line {k}: expected {width} numbers ({kind} pose file), "
                             f"got {len(vals)}")
    arr = np.array(rows.values, dtype=np.float64)
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise InputError(f"{path} line {rows.lines[int(np.flatnonzero(bad)[0])]}: pose is not "
                         "finite")
    if kind == "kitti":
        T = np.tile(np.eye(4), (len(arr), 1, 1))
        T[:, :3, :] = arr.reshape(-1, 3, 4)
        refuse_non_rotations(T[:, :3, :3], str(path), rows.lines)
        return PoseFile(path, kind, T, None)
    if kind == "matrix4":
        return _matrix4(path, rows, arr)
    stamps = np.array([decimal_seconds_to_ns(tok[0], f"{path} line {k}")
                       for k, tok in zip(rows.lines, rows.tokens, strict=True)], np.int64)
    return PoseFile(path, kind, poses_from_quaternions(arr[:, 1:4], arr[:, 4:8], str(path),
                                                       rows.lines), _increasing(path, stamps))


def _matrix4(path: Path, rows: _Rows, arr: F64) -> PoseFile:
    if len(arr) % 4:
        raise InputError(f"{path}: {len(arr)} lines of 4 numbers, a 4x4 pose takes 4 lines")
    T = arr.reshape(-1, 4, 4).copy()
    first_lines = rows.lines[::4]
    for i in range(len(T)):
        if np.any(T[i, 3, :3] != 0.0):
            raise InputError(f"{path} line {first_lines[i] + 3}: the last row of a 4x4 pose "
                             "must be 0 0 0 (1 or the stamp)")
    refuse_non_rotations(T[:, :3, :3], str(path), first_lines)
    corner = T[:, 3, 3].copy()
    T[:, 3, 3] = 1.0
    if np.all(corner == 1.0):
        return PoseFile(path, "matrix4", T, None)
    stamps = seconds_to_ns(corner, str(path))
    return PoseFile(path, "matrix4", T, _increasing(path, stamps))


def _euroc(path: Path, rows: _Rows) -> PoseFile:
    for k, vals in zip(rows.lines, rows.values, strict=True):
        if len(vals) < 8:
            raise InputError(f"{path} line {k}: expected at least 8 values (euroc: timestamp "
                             f"[ns], p x y z, q w x y z), got {len(vals)}")
    arr = np.array([v[:8] for v in rows.values], dtype=np.float64)
    if not np.isfinite(arr).all():
        raise InputError(f"{path}: a pose is not finite")
    stamps = np.array([_ns_token(tok[0], f"{path} line {k}")
                       for k, tok in zip(rows.lines, rows.tokens, strict=True)], np.int64)
    q_xyzw = arr[:, [5, 6, 7, 4]]
    T = poses_from_quaternions(arr[:, 1:4], q_xyzw, str(path), rows.lines)
    return PoseFile(path, "euroc", T, _increasing(path, stamps))


def _ns_token(token: str, what: str) -> int:
    """An EuRoC stamp: integer ns (also written as a float, 1.4036e+18), checked in range."""
    try:
        ns = int(Decimal(token))
    except (InvalidOperation, ValueError):
        raise InputError(f"{what}: EuRoC timestamp {token!r} is not a number of ns") from None
    return check_stamp_ns(ns, what)


def _increasing(path: Path, stamps: NDArray[np.int64]) -> NDArray[np.int64]:
    if np.any(np.diff(stamps) <= 0):
        k = int(np.flatnonzero(np.diff(stamps) <= 0)[0]) + 1
        raise InputError(f"{path}: pose stamps must be strictly increasing (pose {k} is not "
                         f"after pose {k - 1})")
    return stamps


def read_kitti_poses(path: str | Path) -> F64:
    """(N, 4, 4) poses of a KITTI pose file; InputError on a bad line or a non-finite pose."""
    return read_pose_file(path, "kitti").T_world_x


def read_tum(path: str | Path) -> tuple[F64, F64]:
    """(stamps_s (N,), poses (N, 4, 4)) of a TUM file (``#`` comments allowed)."""
    pf = read_pose_file(path, "tum")
    assert pf.stamps_ns is not None
    return pf.stamps_ns / 1e9, pf.T_world_x


def write_kitti_poses(path: str | Path, poses: F64) -> None:
    """Write (N, 4, 4) poses as a KITTI pose file, atomically (%.12e, full precision)."""
    flat = np.asarray(poses, dtype=np.float64)[:, :3, :].reshape(-1, 12)
    lines = [" ".join(f"{v:.12e}" for v in row) for row in flat]
    atomic_write_text(path, "\n".join(lines) + ("\n" if lines else ""))


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
