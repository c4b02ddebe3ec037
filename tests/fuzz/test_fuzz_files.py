"""Fuzz the text and scan file readers: KITTI .bin, times.txt, calib.txt, extrinsics, PCD, and
pose files of every format (fuzz_contract: refuse in one line or give valid output)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from helpers.fuzz_contract import (
    NUMBER_TOKENS,
    RARELY,
    TOKENS,
    fuzz,
    holds,
    is_pose,
    scratch,
    text_lines,
    valid_stamps,
)
from hypothesis import given
from hypothesis import strategies as st
from numpy.typing import NDArray

from pipeline.kitti_calib import read_kitti_calib
from pipeline.posefile import POSE_FORMATS, PoseFile, read_pose_file
from pipeline.sources.poses import read_extrinsic
from pipeline.sources.scanfiles import read_bin, read_pcd
from pipeline.stamps import read_times

# ------------------------------------------------------------------------------- .bin


@fuzz(40)
@given(data=st.one_of(st.binary(max_size=256), st.binary(max_size=16).map(lambda b: b * 16),
                      st.lists(st.floats(width=32), max_size=64).map(
                          lambda v: np.array(v, "<f4").tobytes())))
def test_kitti_bin(tmp_path: Path, data: bytes) -> None:
    with scratch(tmp_path) as d:
        path = d / "000000.bin"
        path.write_bytes(data)
        pts = holds(lambda: read_bin(path), [path])
        if pts is not None:
            assert pts.dtype == np.float32 and pts.shape == (len(data) // 16, 4)


# ------------------------------------------------------------------------------- times / calib

STAMP_TOKENS = st.one_of(
    st.decimals(0, 2**31, allow_nan=False, places=6).map(str), NUMBER_TOKENS, TOKENS)


@fuzz(60)
@given(text=text_lines(STAMP_TOKENS, width=2, lines=6), n_scans=st.none() | st.integers(0, 7))
def test_times_file(tmp_path: Path, text: str, n_scans: int | None) -> None:
    with scratch(tmp_path) as d:
        path = d / "times.txt"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        stamps = holds(lambda: read_times(path, n_scans), [path])
        if stamps is not None:
            assert valid_stamps(stamps) and (n_scans is None or len(stamps) == n_scans)


CALIB_KEYS = st.sampled_from(["Tr:", "Tr_velo_to_cam:", "P0:", "Tr", "tr:", ""])


@fuzz(60)
@given(lines=st.lists(st.tuples(CALIB_KEYS, st.lists(NUMBER_TOKENS | TOKENS, max_size=13)
                                | st.lists(st.floats().map(repr), min_size=12, max_size=12)),
                      max_size=4))
def test_kitti_calib(tmp_path: Path, lines: list[tuple[str, list[str]]]) -> None:
    with scratch(tmp_path) as d:
        path = d / "calib.txt"
        path.write_text("\n".join(f"{k} {' '.join(v)}" for k, v in lines),
                        encoding="utf-8", errors="surrogatepass")
        Tr = holds(lambda: read_kitti_calib(path), [path])
        if Tr is not None:
            assert Tr.shape == (4, 4) and np.isfinite(Tr).all()


@st.composite
def rigid_numbers(draw: st.DrawFn) -> list[str]:
    """12 or 16 numbers of a rigid transform (a unit quaternion's rotation), one sometimes
    replaced."""
    from scipy.spatial.transform import Rotation

    q = np.array(draw(st.tuples(*[st.floats(-1, 1)] * 4)))
    R = Rotation.from_quat(q if np.linalg.norm(q) > 1e-3 else [0, 0, 0, 1]).as_matrix()
    E = np.eye(4)
    E[:3, :3], E[:3, 3] = R, draw(st.tuples(*[st.floats(-10, 10)] * 3))
    numbers = floats(E.ravel()[: draw(st.sampled_from([12, 16]))])
    if draw(st.booleans()):
        numbers[draw(st.integers(0, len(numbers) - 1))] = draw(NUMBER_TOKENS)
    return numbers


@fuzz(60)
@given(numbers=st.lists(NUMBER_TOKENS, max_size=17) | rigid_numbers(),
       sep=st.sampled_from([" ", ",", "\n"]),
       as_file=st.booleans())
def test_extrinsic(tmp_path: Path, numbers: list[str], sep: str, as_file: bool) -> None:
    with scratch(tmp_path) as d:
        value: str | Path = sep.join(numbers)
        inputs = []
        if as_file:
            value = d / "extrinsic.txt"
            value.write_text(sep.join(numbers))
            inputs = [value]
        E = holds(lambda: read_extrinsic(value), inputs)
        if E is not None:
            assert E.shape == (4, 4) and is_pose(E, tol=1e-3)


# ------------------------------------------------------------------------------- PCD

PCD_FIELDS = st.sampled_from(["x", "y", "z", "intensity", "t", "time", "rgb", "ring", "x"])
PCD_TYPE_SIZE = st.sampled_from(
    [("F", "4"), ("F", "8"), ("U", "1"), ("U", "2"), ("I", "4"), ("U", "8"), ("F", "2"),
     ("Q", "4"), ("F", "x")])


@st.composite
def pcd_files(draw: st.DrawFn) -> bytes:
    """A PCD v0.7 file: a header mostly right (x y z first), some values or lines broken, and
    an ascii or binary body of about the right size."""
    names = ["x", "y", "z", *draw(st.lists(PCD_FIELDS, max_size=3))]
    if draw(st.booleans()):
        names = draw(st.permutations(names))[: draw(st.integers(1, len(names)))]
    types = [draw(PCD_TYPE_SIZE) if draw(RARELY) else ("F", "4") for _ in names]
    counts = [draw(st.sampled_from(["2", "0", "-1"])) if draw(RARELY) else "1" for _ in names]
    width = draw(st.integers(0, 5))
    count_tok = lambda n: draw(NUMBER_TOKENS) if draw(RARELY) else str(n)  # noqa: E731
    data = draw(st.sampled_from(["ascii", "binary", "ascii", "binary", "binary_compressed",
                                 "BINARY", "text"]))
    header = {
        "VERSION": "0.7", "FIELDS": " ".join(names),
        "SIZE": " ".join(s for _, s in types), "TYPE": " ".join(t for t, _ in types),
        "COUNT": " ".join(counts), "WIDTH": count_tok(width), "HEIGHT": count_tok(1),
        "VIEWPOINT": "0 0 0 1 0 0 0", "POINTS": count_tok(width), "DATA": data,
    }
    dropped = draw(st.sets(st.sampled_from(sorted(header)), max_size=2)) \
        if draw(RARELY) else set()
    text = "".join(f"{k} {v}\n" for k, v in header.items() if k not in dropped)
    if data.lower() == "ascii":
        row = st.lists(st.floats(width=32).map(repr) | NUMBER_TOKENS,
                       min_size=len(names), max_size=len(names) + 1).map(" ".join)
        body = "\n".join(draw(st.lists(row, min_size=max(width - 1, 0), max_size=width + 1)))
        return (text + body).encode("utf-8", "surrogatepass")
    return text.encode() + draw(st.binary(max_size=120))


@fuzz(80)
@given(data=pcd_files())
def test_pcd(tmp_path: Path, data: bytes) -> None:
    with scratch(tmp_path) as d:
        path = d / "scan.pcd"
        path.write_bytes(data)
        scan = holds(lambda: read_pcd(path), [path])
        if scan is not None:
            assert scan.points.dtype == np.float32 and scan.points.ndim == 2
            assert scan.points.shape[1] == 4
            assert scan.time is None or scan.time.shape == (len(scan.points),)


# ------------------------------------------------------------------------------- pose files


def floats(values: NDArray[np.float64]) -> list[str]:
    return [repr(float(v)) for v in values]


@st.composite
def pose_rows(draw: st.DrawFn, fmt: str) -> list[list[str]]:
    """Rows of a pose file of ``fmt``: right poses from unit quaternions, then a few tokens
    replaced (a wrong number, a word, a NaN, a missing value)."""
    n = draw(st.integers(1, 4))
    q = np.array(draw(st.lists(st.tuples(*[st.floats(-1, 1)] * 4), min_size=n, max_size=n)))
    q[np.linalg.norm(q, axis=1) < 1e-3] = [0, 0, 0, 1]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t = np.array(draw(st.lists(st.tuples(*[st.floats(-1e3, 1e3)] * 3), min_size=n,
                               max_size=n)))
    stamps = np.cumsum(draw(st.lists(st.floats(1e-3, 2.0), min_size=n, max_size=n))) + \
        draw(st.floats(0, 2e9))
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(q).as_matrix()
    rows: list[list[str]] = []
    for k in range(n):
        if fmt == "kitti":
            rows.append([repr(float(v)) for v in np.hstack([R[k], t[k][:, None]]).ravel()])
        elif fmt == "tum":
            rows.append([f"{stamps[k]:.9f}", *floats(t[k]), *floats(q[k])])
        elif fmt == "euroc":
            rows.append([str(int(stamps[k] * 1e9)), *floats(t[k]), *floats(q[k][[3, 0, 1, 2]])])
        else:  # matrix4
            M = np.eye(4)
            M[:3, :3], M[:3, 3] = R[k], t[k]
            M[3, 3] = draw(st.sampled_from([1.0, float(stamps[k])]))
            rows.extend([floats(r) for r in M])
    for _ in range(draw(st.integers(0, 3)) // 2):
        row = draw(st.integers(0, len(rows) - 1))
        if rows[row]:
            col = draw(st.integers(0, len(rows[row]) - 1))
            if draw(st.booleans()):
                rows[row][col] = draw(NUMBER_TOKENS | TOKENS)
            else:
                del rows[row][col]
    return rows


@st.composite
def pose_files(draw: st.DrawFn) -> tuple[str, str]:
    """(text of a pose file, the format asked for: one of POSE_FORMATS)."""
    fmt = draw(st.sampled_from(["kitti", "tum", "euroc", "matrix4"]))
    rows = draw(pose_rows(fmt))
    sep = "," if fmt == "euroc" else " "
    head = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w []\n" \
        if fmt == "euroc" and draw(st.booleans()) else draw(st.sampled_from(["", "# poses\n"]))
    asked = draw(st.sampled_from([fmt, "auto", *POSE_FORMATS]))
    return head + "\n".join(sep.join(r) for r in rows) + "\n", asked


@fuzz(150)
@given(file=pose_files())
def test_pose_file(tmp_path: Path, file: tuple[str, str]) -> None:
    text, fmt = file
    with scratch(tmp_path) as d:
        path = d / "poses.txt"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        poses: PoseFile | None = holds(lambda: read_pose_file(path, fmt), [path])  # type: ignore[arg-type]
        if poses is not None:
            assert poses.T_world_x.ndim == 3 and len(poses.T_world_x) >= 1
            assert is_pose(poses.T_world_x)
            assert poses.stamps_ns is None or (
                len(poses.stamps_ns) == len(poses.T_world_x) and valid_stamps(poses.stamps_ns))
