"""Single-scan files: KITTI .bin, PCD (ascii / binary; binary_compressed via open3d), PLY.

Every reader returns (N, 4) float32 x, y, z [m] and intensity (zeros when the file has none),
non-finite points included (the writer drops and counts them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

SCAN_SUFFIXES = (".bin", ".pcd", ".ply")
INTENSITY_NAMES = ("intensity", "reflectance", "i", "remission")


def read_scan(path: Path) -> NDArray[np.float32]:
    """(N, 4) float32 points of a .bin, .pcd or .ply file."""
    suffix = path.suffix.lower()
    if suffix == ".bin":
        return read_bin(path)
    if suffix == ".pcd":
        return read_pcd(path)
    if suffix == ".ply":
        return read_open3d(path)
    raise InputError(f"{path}: unknown scan file type (expected one of {', '.join(SCAN_SUFFIXES)})")


def read_bin(path: Path) -> NDArray[np.float32]:
    """(N, 4) float32 of a KITTI velodyne .bin (x, y, z, reflectance, little endian)."""
    size = path.stat().st_size
    if size % 16:
        raise InputError(
            f"{path}: size {size} bytes is not a multiple of 16 "
            "(float32 x, y, z, reflectance per point): truncated scan?"
        )
    return np.fromfile(path, dtype="<f4").reshape(-1, 4)


_PCD_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    ("I", 1): "i1",
    ("I", 2): "i2",
    ("I", 4): "i4",
    ("I", 8): "i8",
    ("U", 1): "u1",
    ("U", 2): "u2",
    ("U", 4): "u4",
    ("U", 8): "u8",
}


def read_pcd(path: Path) -> NDArray[np.float32]:
    """(N, 4) float32 of a PCD v0.7 file (DATA ascii or binary; binary_compressed via open3d)."""
    with open(path, "rb") as fh:
        header: dict[str, list[str]] = {}
        while True:
            line = fh.readline()
            if not line:
                raise InputError(f"{path}: PCD header has no DATA line (truncated or not a PCD)")
            text = line.decode("ascii", errors="replace").strip()
            if not text or text.startswith("#"):
                continue
            key, *vals = text.split()
            header[key.upper()] = vals
            if key.upper() == "DATA":
                break
        body = fh.read()
    data = header["DATA"][0].lower() if header["DATA"] else ""
    if data == "binary_compressed":
        return read_open3d(path)
    dtype, names = _pcd_dtype(path, header)
    n = int(header.get("POINTS", [0])[0] or 0) or _pcd_width(header)
    if data == "binary":
        if len(body) < n * dtype.itemsize:
            raise InputError(
                f"{path}: PCD data is {len(body)} bytes, expected {n * dtype.itemsize} "
                f"({n} points of {dtype.itemsize} bytes): truncated"
            )
        rec = np.frombuffer(body, dtype=dtype, count=n)
    elif data == "ascii":
        try:
            table = np.loadtxt(body.decode("ascii").splitlines(), dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise InputError(f"{path}: malformed ascii PCD data ({exc})") from None
        if table.shape[0] != n or table.shape[1] != len(dtype.names or ()):
            raise InputError(
                f"{path}: PCD has {table.shape[0]}x{table.shape[1]} values, header "
                f"says {n} points x {len(dtype.names or ())} fields"
            )
        rec = np.zeros(n, dtype=dtype)
        for k, name in enumerate(dtype.names or ()):
            rec[name] = table[:, k]
    else:
        raise InputError(f"{path}: unsupported PCD DATA {data!r}")
    return _xyzi(rec, names, path)


def _pcd_width(header: dict[str, list[str]]) -> int:
    w = int(header.get("WIDTH", ["0"])[0])
    h = int(header.get("HEIGHT", ["1"])[0])
    return w * h


def _pcd_dtype(path: Path, header: dict[str, list[str]]) -> tuple[np.dtype, list[str]]:
    try:
        names = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = [t.upper() for t in header["TYPE"]]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(names))]
    except (KeyError, ValueError) as exc:
        raise InputError(f"{path}: malformed PCD header ({exc})") from None
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise InputError(f"{path}: PCD header FIELDS/SIZE/TYPE/COUNT lengths differ")
    fields = []
    for k, (name, size, typ, count) in enumerate(zip(names, sizes, types, counts, strict=True)):
        code = _PCD_TYPES.get((typ, size))
        if code is None:
            raise InputError(f"{path}: PCD field {name!r} has unknown TYPE {typ} SIZE {size}")
        fields.append(
            (f"{name}#{k}", "<" + code, (count,)) if count > 1 else (f"{name}#{k}", "<" + code)
        )
    dtype = np.dtype(fields)
    return dtype, [n.split("#")[0] for n in dtype.names or ()]


def _xyzi(rec: NDArray, names: list[str], path: Path) -> NDArray[np.float32]:
    by_name = {n: full for n, full in zip(names, rec.dtype.names or (), strict=True)}
    missing = [a for a in "xyz" if a not in by_name]
    if missing:
        raise InputError(f"{path}: no field {', '.join(missing)} (fields: {', '.join(names)})")
    out = np.zeros((len(rec), 4), np.float32)
    for col, name in enumerate("xyz"):
        field = rec[by_name[name]]
        if field.dtype.kind != "f":
            raise InputError(f"{path}: field {name!r} is {field.dtype}, x, y, z must be float")
        out[:, col] = field
    inten = next((by_name[n] for n in INTENSITY_NAMES if n in by_name), None)
    if inten is not None and rec[inten].ndim == 1:
        out[:, 3] = rec[inten]
    return out


def read_open3d(path: Path) -> NDArray[np.float32]:
    """(N, 4) float32 of any point-cloud file open3d reads (.ply, compressed .pcd)."""
    import open3d as o3d  # heavy: only for the formats we do not parse ourselves

    pcd = o3d.t.io.read_point_cloud(path)
    if "positions" not in pcd.point or len(pcd.point.positions) == 0:
        raise InputError(f"{path}: open3d read no points (corrupt, empty or unsupported file)")
    xyz = pcd.point.positions.numpy()
    if xyz.dtype.kind != "f":
        raise InputError(f"{path}: positions are {xyz.dtype}, x, y, z must be float")
    out = np.zeros((len(xyz), 4), np.float32)
    out[:, :3] = xyz
    for name in INTENSITY_NAMES:
        if name in pcd.point:
            out[:, 3] = pcd.point[name].numpy().reshape(len(xyz), -1)[:, 0]
            break
    return out
