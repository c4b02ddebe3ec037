"""Scans handed to an external tool as files (the ``command`` adapter's ``scans`` option).

- ``kitti``: KITTI's layout, ``<folder>/velodyne/NNNNNN.bin`` (float32 x, y, z, intensity a
  point, as KITTI's velodyne scans) and ``<folder>/times.txt``;
- ``pcd``: ``<folder>/NNNNNN.pcd`` (binary PCD v0.7, float32 fields x y z intensity, and ``t``,
  the point's time [s] from the scan's stamp, where the sequence has per-point time) and
  ``<folder>/times.txt``.

``times.txt``: the scans' stamps [s] (stamp_ns / 1e9, 9 decimals), one a line, frame k on line
k + 1: the stamps a tool's TUM trajectory must carry. Files are numbered by frame from 000000.

``scan_folder(scans, layout, cache)`` writes them once per sequence file when ``cache`` is a
folder (keyed by the file's name, size and modification time; a finished folder is renamed
into place, so concurrent trials never see half of one), else into a fresh folder.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.sequence import Scan

ScanLayout = Literal["kitti", "pcd"]
LAYOUTS: tuple[str, ...] = ("kitti", "pcd")


def scan_folder(scans: Iterable[Scan], layout: ScanLayout, work: Path,
                cache: str | Path | None = None) -> tuple[Path, NDArray[np.int64]]:
    """(folder, stamps_ns) of ``scans`` written in ``layout`` (module docstring): into
    ``work``/scans, or into ``cache`` once per sequence file."""
    path = getattr(scans, "path", None)
    if cache is None or path is None or not Path(path).is_file():
        return work / "scans", write_scans(scans, layout, work / "scans")
    final = Path(cache) / f"{Path(path).stem}-{layout}-{_key(Path(path))}"
    if not (final / "times.txt").is_file():
        Path(cache).mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=cache))
        try:
            write_scans(scans, layout, tmp)
            os.rename(tmp, final)
        except OSError:
            if not (final / "times.txt").is_file():  # not another trial's, finished first
                raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    times = np.loadtxt(final / "times.txt", dtype=np.float64, ndmin=1)
    return final, np.asarray(getattr(scans, "stamps_ns", np.round(times * 1e9)), np.int64)


def write_scans(scans: Iterable[Scan], layout: ScanLayout, folder: Path) -> NDArray[np.int64]:
    """Write ``scans`` into ``folder`` in ``layout``; their stamps [ns]."""
    files = folder / "velodyne" if layout == "kitti" else folder
    files.mkdir(parents=True, exist_ok=True)
    stamps = []
    for k, scan in enumerate(scans):
        if layout == "kitti":
            write_bin(files / f"{k:06d}.bin", scan.points_lidar)
        else:
            write_pcd(files / f"{k:06d}.pcd", scan.points_lidar, scan.time_s)
        stamps.append(scan.stamp_ns)
    stamps_ns = np.asarray(stamps, np.int64)
    (folder / "times.txt").write_text("".join(f"{s // 10**9}.{s % 10**9:09d}\n"
                                              for s in stamps_ns.tolist()))
    return stamps_ns


def write_bin(path: Path, points: NDArray[np.float32]) -> None:
    """A KITTI velodyne scan: (N, 4) float32 x, y, z, intensity, little-endian, no header."""
    np.ascontiguousarray(points[:, :4], "<f4").tofile(path)


def write_pcd(path: Path, points: NDArray[np.float32],
              time_s: NDArray[np.float32] | None = None) -> None:
    """A binary PCD v0.7 of float32 x, y, z, intensity (and ``t`` [s] when given)."""
    names = ["x", "y", "z", "intensity", *(["t"] if time_s is not None else [])]
    cols = [points[:, i] for i in range(4)] + ([time_s] if time_s is not None else [])
    data = np.ascontiguousarray(np.stack(cols, axis=1), "<f4")
    head = (f"VERSION 0.7\nFIELDS {' '.join(names)}\nSIZE {' '.join('4' for _ in names)}\n"
            f"TYPE {' '.join('F' for _ in names)}\nCOUNT {' '.join('1' for _ in names)}\n"
            f"WIDTH {len(data)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(data)}\n"
            "DATA binary\n")
    path.write_bytes(head.encode() + data.tobytes())


def _key(path: Path) -> str:
    """A short key of a file's name, size and modification time."""
    st = path.stat()
    text = f"{path.resolve()}:{st.st_size}:{st.st_mtime_ns}"
    return hashlib.sha256(text.encode()).hexdigest()[:12]
