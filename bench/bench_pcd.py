"""PCD reading: adaptune's parser (pipeline/sources/scanfiles.py) against open3d's, same run.

A real KITTI scan (sequence 04, ~124k points, float32 x, y, z, intensity) written as a binary,
an ascii and a binary_compressed PCD. Our parser reads binary and ascii data, open3d's reads
binary_compressed (LZF). The last row is the other reason to keep ours: open3d reads an ascii
PCD whose data stops early (the header says 5 points, 2 follow) without an error and returns
uninitialised memory for the missing points; ours refuses it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from common import Row, best_of, data_root, size


def _write(path: Path, pts: np.ndarray, data: str) -> None:
    head = ("VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
            f"WIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\n"
            f"DATA {data}\n")
    body = (pts.astype("<f4").tobytes() if data == "binary"
            else "\n".join(" ".join(f"{v:.9g}" for v in row) for row in pts).encode() + b"\n")
    path.write_bytes(head.encode() + body)


def run() -> list[Row]:
    import open3d as o3d

    from pipeline.errors import InputError
    from pipeline.sources.scanfiles import read_open3d, read_pcd

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    scan = data_root() / "kitti_mini" / "dataset" / "sequences" / "04" / "velodyne" / "000000.bin"
    pts = np.fromfile(scan, np.float32).reshape(-1, 4)[:size(None, 2000)]
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        binary, ascii_, comp = Path(tmp) / "b.pcd", Path(tmp) / "a.pcd", Path(tmp) / "c.pcd"
        _write(binary, pts, "binary")
        _write(ascii_, pts, "ascii")
        o3d.t.io.write_point_cloud(str(comp), o3d.t.io.read_point_cloud(str(binary)),
                                   compressed=True)
        for path, kind, repeat in ((binary, "binary", 7), (ascii_, "ascii", 2)):
            assert np.array_equal(read_pcd(path).points, read_open3d(path).points)
            ours = best_of(lambda p=path: read_pcd(p), repeat)
            theirs = best_of(lambda p=path: read_open3d(p), repeat)
            article = "an" if kind == "ascii" else "a"
            rows.append(Row(f"read {article} {kind} PCD, {len(pts)} points (ours)", 1e3 * ours,
                            "ms",
                            f"open3d: {1e3 * theirs:.2f} ms ({theirs / ours:.1f}x)",
                            "open3d unless a measured reason"))
        t_comp = best_of(lambda: read_pcd(comp), 3)
        rows.append(Row(f"read a binary_compressed PCD, {len(pts)} points (open3d)",
                        1e3 * t_comp, "ms", "LZF: open3d's reader", ""))
        short = Path(tmp) / "short.pcd"
        _write(short, pts[:5], "ascii")
        text = short.read_text().splitlines()
        short.write_text("\n".join(text[:-3]) + "\n")  # 2 of the 5 points left
        got = read_open3d(short).points
        try:
            read_pcd(short)
            ours_refuses = "ours: accepted"
        except InputError:
            ours_refuses = "ours: refused (one line)"
        rows.append(Row("open3d: points returned from a truncated ascii PCD (2 of 5 present)",
                        float(len(got)), "points", ours_refuses, "refuse"))
    return rows
