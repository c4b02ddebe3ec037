"""Single-scan files: KITTI .bin, PCD (ascii, binary; binary_compressed via open3d), PLY (open3d).

Every reader returns a ``ScanFile``: (N, 4) float32 x, y, z [m] and intensity (zeros when the
file has none), non-finite points included (the writer drops and counts them), and the raw
per-point time column when the file has one (``t``, ``time``, ``timestamp``, ``offset_time``).

The PCD parser is our own for ascii and binary data, open3d's for binary_compressed: measured in
``make bench`` (bench/bench_pcd.py), open3d reads a binary 124k-point PCD ~100x slower and
returns uninitialised memory, without an error, for a truncated or malformed ascii PCD. The
header is always checked here, so a bad one is one line naming the file and the rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

SCAN_SUFFIXES = (".bin", ".pcd", ".ply")
INTENSITY_NAMES = ("intensity", "reflectance", "i", "remission")
TIME_NAMES = ("t", "time", "timestamp", "offset_time")
"""Per-point time fields of common drivers (Ouster t [ns], Velodyne time [s], Hesai timestamp
[s, absolute], Livox offset_time [ns])."""


@dataclass(frozen=True)
class ScanFile:
    """One scan file read: ``points`` (N, 4) float32 x, y, z [m], intensity (as stored);
    ``time`` (N,) the per-point time column as stored (any dtype) and ``time_field`` its name,
    or None."""

    points: NDArray[np.float32]
    time: NDArray | None = None
    time_field: str | None = None


def scan_files(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    """The files of ``folder`` with one of ``suffixes``, unsorted; InputError when there is
    none, or when such a name is not a regular file (a folder named ``x.bin``)."""
    found = [p for p in folder.iterdir() if p.suffix.lower() in suffixes]
    for p in found:
        if not p.is_file():
            raise InputError(f"{p}: is not a regular file (a scan must be a file)")
    if not found:
        raise InputError(f"{folder}: no scan files ({', '.join(suffixes)})")
    return found


def read_scan(path: Path) -> ScanFile:
    """The points (and per-point time) of a .bin, .pcd or .ply file."""
    suffix = path.suffix.lower()
    if suffix == ".bin":
        return ScanFile(read_bin(path))
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
    ("F", 4): "f4", ("F", 8): "f8",
    ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
    ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
}
_PCD_DATA = ("ascii", "binary", "binary_compressed")


@dataclass(frozen=True)
class PcdHeader:
    """A checked PCD v0.7 header: field ``names``, record ``dtype``, ``points``, ``data``."""

    names: list[str]
    dtype: np.dtype
    points: int
    data: str


def read_pcd(path: Path) -> ScanFile:
    """The points of a PCD v0.7 file (module docstring: which parser reads which DATA)."""
    with open(path, "rb") as fh:
        header = _pcd_header(path, fh)
        if header.data == "binary_compressed":
            fh.close()
            scan = read_open3d(path)
            if len(scan.points) != header.points:
                raise InputError(f"{path}: open3d read {len(scan.points)} points, the header "
                                 f"says POINTS {header.points} (damaged compressed data?)")
            return scan
        body = fh.read()
    if header.data == "binary":
        need = header.points * header.dtype.itemsize
        if len(body) < need:
            raise InputError(f"{path}: PCD data is {len(body)} bytes, expected {need} "
                             f"({header.points} points of {header.dtype.itemsize} bytes): "
                             "truncated")
        rec = np.frombuffer(body, dtype=header.dtype, count=header.points)
    else:
        rec = _pcd_ascii(path, body, header)
    return _scan_of_record(rec, header.names, path)


def _pcd_header(path: Path, fh) -> PcdHeader:  # type: ignore[no-untyped-def]
    """Parse and check the header lines up to DATA; InputError naming the rule broken."""
    fields: dict[str, list[str]] = {}
    while True:
        line = fh.readline()
        if not line:
            raise InputError(f"{path}: PCD header has no DATA line (truncated or not a PCD)")
        text = line.decode("ascii", errors="replace").strip()
        if not text or text.startswith("#"):
            continue
        key, *vals = text.split()
        fields[key.upper()] = vals
        if key.upper() == "DATA":
            break
    try:
        names = fields["FIELDS"]
        sizes, types = fields["SIZE"], [t.upper() for t in fields["TYPE"]]
    except KeyError as exc:
        raise InputError(f"{path}: PCD header has no {exc.args[0]} line") from None
    counts = fields.get("COUNT", ["1"] * len(names))
    sizes_i = [_header_int(path, "SIZE", s, 1) for s in sizes]
    counts_i = [_header_int(path, "COUNT", c, 1) for c in counts]
    if not len(names) == len(sizes_i) == len(types) == len(counts_i):
        raise InputError(f"{path}: PCD header FIELDS/SIZE/TYPE/COUNT lengths differ")
    width = _header_int(path, "WIDTH", (fields.get("WIDTH") or ["?"])[0], 0)
    height = _header_int(path, "HEIGHT", (fields.get("HEIGHT") or ["1"])[0], 1)
    points = _header_int(path, "POINTS", (fields.get("POINTS") or [str(width * height)])[0], 0)
    if points != width * height:
        raise InputError(f"{path}: PCD header says POINTS {points} but WIDTH x HEIGHT = "
                         f"{width} x {height} = {width * height}")
    data = (fields["DATA"] or [""])[0].lower()
    if data not in _PCD_DATA:
        raise InputError(f"{path}: unsupported PCD DATA {data!r} (known: {', '.join(_PCD_DATA)})")
    dtype_fields = []
    for k, (name, size, typ, count) in enumerate(zip(names, sizes_i, types, counts_i,
                                                     strict=True)):
        code = _PCD_TYPES.get((typ, size))
        if code is None:
            raise InputError(f"{path}: PCD field {name!r} has unknown TYPE {typ} SIZE {size}")
        dtype_fields.append((f"{name}#{k}", "<" + code, (count,)) if count > 1
                            else (f"{name}#{k}", "<" + code))
    return PcdHeader(list(names), np.dtype(dtype_fields), points, data)


def _header_int(path: Path, key: str, value: str, low: int) -> int:
    """An integer header value >= ``low``, or InputError naming the key and the value."""
    try:
        number = int(value)
    except ValueError:
        raise InputError(f"{path}: PCD header {key} must be an integer >= {low}, "
                         f"got {value!r}") from None
    if number < low:
        raise InputError(f"{path}: PCD header {key} must be an integer >= {low}, got {number}")
    return number


def _pcd_ascii(path: Path, body: bytes, header: PcdHeader) -> NDArray:
    """The records of an ascii PCD body, counted and parsed strictly."""
    n_values = sum(int(np.prod(header.dtype[k].shape or (1,))) for k in range(len(header.names)))
    try:
        lines = [ln for ln in body.decode("ascii").splitlines() if ln.strip()]
        table = (np.loadtxt(lines, dtype=np.float64, ndmin=2) if lines
                 else np.zeros((0, n_values)))  # loadtxt warns on no data
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: malformed ascii PCD data ({exc})") from None
    if table.shape != (header.points, n_values):
        raise InputError(f"{path}: PCD has {table.shape[0]}x{table.shape[1]} values, the "
                         f"header says {header.points} points x {n_values} values")
    rec = np.zeros(header.points, dtype=header.dtype)
    col = 0
    for field, name in zip(header.names, header.dtype.names or (), strict=True):
        width = int(np.prod(header.dtype[name].shape or (1,)))
        values = table[:, col : col + width]
        _check_fits(path, field, values, header.dtype[name].base)
        rec[name] = values.reshape(rec[name].shape)
        col += width
    return rec


def _check_fits(path: Path, name: str, values: NDArray, kind: np.dtype) -> None:
    """InputError naming the field when a value of the ascii body does not fit its declared
    type: beyond a float type's range (it would become inf), or beyond an integer type's range
    or not finite (it would wrap or be undefined)."""
    info = np.finfo(kind) if kind.kind == "f" else np.iinfo(kind)
    finite = np.isfinite(values)
    bad = ~finite if kind.kind != "f" else np.zeros_like(finite)
    bad |= finite & ((values > info.max) | (values < info.min))
    if bad.any():
        raise InputError(f"{path}: PCD field {name} holds {float(values[bad][0]):g}, which does "
                         f"not fit its type {kind} (range {info.min:g} to {info.max:g})")


def _scan_of_record(rec: NDArray, names: list[str], path: Path) -> ScanFile:
    by_name = {n: full for n, full in zip(names, rec.dtype.names or (), strict=True)}
    columns = {n: rec[full] for n, full in by_name.items() if rec[full].ndim == 1}
    return _scan_of_columns(columns, path)


def _scan_of_columns(columns: dict[str, NDArray], path: Path) -> ScanFile:
    """ScanFile of named (N,) columns: x, y, z (float), intensity and time when present."""
    missing = [a for a in "xyz" if a not in columns]
    if missing:
        raise InputError(f"{path}: no field {', '.join(missing)} "
                         f"(fields: {', '.join(columns)})")
    n = len(columns["x"])
    out = np.zeros((n, 4), np.float32)
    for col, name in enumerate("xyz"):
        if columns[name].dtype.kind != "f":
            raise InputError(f"{path}: field {name!r} is {columns[name].dtype}, "
                             "x, y, z must be float")
        out[:, col] = columns[name]
    inten = next((n for n in INTENSITY_NAMES if n in columns), None)
    if inten is not None:
        out[:, 3] = columns[inten]
    time_field = next((n for n in TIME_NAMES if n in columns), None)
    return ScanFile(out, None if time_field is None else columns[time_field].copy(), time_field)


def read_open3d(path: Path) -> ScanFile:
    """The points of any point-cloud file open3d reads (.ply, compressed .pcd)."""
    import open3d as o3d  # heavy: only for the formats we do not parse ourselves

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    pcd = o3d.t.io.read_point_cloud(str(path))  # type: ignore[arg-type]
    if "positions" not in pcd.point or len(pcd.point.positions) == 0:
        raise InputError(f"{path}: open3d read no points (corrupt, empty or unsupported file)")
    xyz = pcd.point.positions.numpy()
    columns = {name: xyz[:, k] for k, name in enumerate("xyz")}
    for name in (*INTENSITY_NAMES, *TIME_NAMES):
        if name in pcd.point:
            columns[name] = pcd.point[name].numpy().reshape(len(xyz), -1)[:, 0]
    return _scan_of_columns(columns, path)
