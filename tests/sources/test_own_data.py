"""Bring your own data (issue 14): scan order, pose formats, extrinsic and the camera-frame
warning, sensor name, PCD intensity scaling and per-point time, on real KITTI scans written as
PCD files by hand."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.source_inputs import (
    KittiFrames,
    load_kitti,
    point_times_s,
    write_kitti_poses,
    write_tum,
)
from scipy.spatial.transform import Rotation

from pipeline.posefile import read_pose_file
from pipeline.sequence import SequenceReader
from stages.cli import main

N = 10  # names full0, full7, .. full63: plain string order puts full14 before full7


@pytest.fixture(scope="module")
def frames(kitti_root: Path) -> KittiFrames:
    kf = load_kitti(kitti_root, "04", N)
    return replace(kf, points=[p[:2000] for p in kf.points])


def write_pcd(path: Path, xyzi: np.ndarray, intensity: str = "F", time_s: np.ndarray | None = None
              ) -> None:
    """A binary PCD of float32 x, y, z and intensity (F: float 0-1 as stored; U: uint8 0-255),
    with a float32 ``t`` field when ``time_s`` is given."""
    names, sizes, types = ["x", "y", "z", "intensity"], ["4", "4", "4", "4"], ["F", "F", "F", "F"]
    cols = [xyzi[:, 0], xyzi[:, 1], xyzi[:, 2], xyzi[:, 3]]
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")]
    if intensity == "U":
        sizes[3], types[3], dtype[3] = "1", "U", ("intensity", "u1")
        cols[3] = np.round(xyzi[:, 3] * 255)
    if time_s is not None:
        names.append("t"), sizes.append("4"), types.append("F"), dtype.append(("t", "<f4"))
        cols.append(time_s)
    rec = np.zeros(len(xyzi), dtype)
    for (name, _), col in zip(dtype, cols, strict=True):
        rec[name] = col
    head = (f"VERSION 0.7\nFIELDS {' '.join(names)}\nSIZE {' '.join(sizes)}\n"
            f"TYPE {' '.join(types)}\nCOUNT {' '.join('1' for _ in names)}\nWIDTH {len(xyzi)}\n"
            f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(xyzi)}\nDATA binary\n")
    path.write_bytes(head.encode() + rec.tobytes())


def scan_folder(tmp: Path, kf: KittiFrames, **kw: object) -> Path:
    d = tmp / "scans"
    d.mkdir(exist_ok=True)
    for k, pts in enumerate(kf.points):
        write_pcd(d / f"full{7 * k}.pcd", pts, **kw)  # type: ignore[arg-type]
    return d


def ingest(*args: object) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, ["ingest", "folder", *map(str, args)])
    return result.exit_code, result.stdout, result.stderr


def test_scans_take_their_own_pose_in_natural_order(frames: KittiFrames, tmp_path: Path,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    """full0, full7, .. full63 with a LiDAR-frame TUM pose file: scan k gets pose k (string order
    gave 2 of 177 scans their own pose in the issue). Sensor and intensity go on record."""
    d = scan_folder(tmp_path, frames)
    write_tum(tmp_path / "gt.tum", frames.stamps_ns, frames.T_world_lidar)
    code, _, err = ingest(d, "--poses", tmp_path / "gt.tum", "--sensor", "hdl64",
                            "--out", tmp_path / "s.mcap")
    assert code == 0, err
    with SequenceReader(tmp_path / "s.mcap") as r:
        for k in (1, 2, 9):
            np.testing.assert_array_equal(r[k].points_lidar, frames.points[k])
        np.testing.assert_allclose(r.ground_truth(), frames.T_world_lidar, atol=1e-6)
        np.testing.assert_array_equal(r.stamps_ns, frames.stamps_ns)
        assert r.info.sensor == "hdl64" and r.info.extra["intensity"] == "0-1 as recorded"
        assert r.info.extra["stamps"] == "pose file gt.tum"
    assert "z axis" not in caplog.text


@pytest.mark.parametrize("names, rule", [
    (["scan1.pcd", "scan01.pcd"], "carry the same number"),
    (["a1.pcd", "b2.pcd"], "differ in more than their numbers"),
    (["first.pcd", "second.pcd"], "differ in more than their numbers"),
])
def test_ambiguous_names_are_refused(frames: KittiFrames, tmp_path: Path, names: list[str],
                                     rule: str) -> None:
    d = tmp_path / "scans"
    d.mkdir()
    for name in names:
        write_pcd(d / name, frames.points[0])
    code, _, err = ingest(d, "--out", tmp_path / "s.mcap")
    assert code == 1 and "cannot order the scans by name" in err and rule in err, err


def test_stamps_from_file_names(frames: KittiFrames, tmp_path: Path) -> None:
    d = tmp_path / "scans"
    d.mkdir()
    names = ["1317000000.95", "1317000001.05", "1317000000.85"]  # 0.85 < 0.95 < 1.05
    for name, pts in zip(names, frames.points, strict=False):
        write_pcd(d / f"{name}.pcd", pts)
    code, _, err = ingest(d, "--out", tmp_path / "s.mcap")
    assert code == 0, err
    with SequenceReader(tmp_path / "s.mcap") as r:
        assert r.stamps_ns.tolist() == [1317000000_850000000, 1317000000_950000000,
                                        1317000001_050000000]
        np.testing.assert_array_equal(r[0].points_lidar, frames.points[2])
    d = tmp_path / "ns"  # integer ns names (18 digits and more)
    d.mkdir()
    for name, pts in zip(["1317000000950000000", "1317000000850000000"], frames.points,
                         strict=False):
        write_pcd(d / f"{name}.pcd", pts)
    code, _, err = ingest(d, "--out", tmp_path / "n.mcap")
    assert code == 0, err
    with SequenceReader(tmp_path / "n.mcap") as r:
        assert r.stamps_ns.tolist() == [1317000000_850000000, 1317000000_950000000]
        np.testing.assert_array_equal(r[0].points_lidar, frames.points[1])


def pose_file_variants(kf: KittiFrames, tmp: Path) -> dict[str, Path]:
    """The LiDAR poses of ``kf`` in every format, written by hand."""
    T, t_s = kf.T_world_lidar, kf.stamps_ns / 1e9 + 100.0
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # x y z w
    paths = {"kitti": tmp / "p.kitti", "tum": tmp / "p.tum", "euroc": tmp / "data.csv",
             "matrix4": tmp / "p.mat", "matrix4_stamped": tmp / "p_stamped.mat"}
    write_kitti_poses(paths["kitti"], T)
    write_tum(paths["tum"], kf.stamps_ns + 100 * 10**9, T)
    rows = ["#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],"
            "q_RS_z [],v_RS_R_x [m s^-1]"]
    stamps_ns = kf.stamps_ns + 100 * 10**9
    rows += [f"{ns},{p[0]:.12g},{p[1]:.12g},{p[2]:.12g},{qq[3]:.15g},{qq[0]:.15g},{qq[1]:.15g},"
             f"{qq[2]:.15g},0.0" for ns, p, qq in zip(stamps_ns, T[:, :3, 3], q, strict=True)]
    paths["euroc"].write_text("\n".join(rows) + "\n")
    blocks = ["\n".join(" ".join(f"{v:.15g}" for v in row) for row in P) for P in T]
    paths["matrix4"].write_text("\n".join(blocks) + "\n")
    stamped = T.copy()
    stamped[:, 3, 3] = t_s
    paths["matrix4_stamped"].write_text(
        "\n".join("\n".join(" ".join(f"{v:.15g}" for v in row) for row in P) for P in stamped))
    return paths


def test_the_format_hint_names_every_format_that_fits(frames: KittiFrames,
                                                      tmp_path: Path) -> None:
    """4x4 blocks with trailing commas fit matrix4 alone: read as such (issue 57.5, they were
    refused with a hint of euroc or tum); a CSV of 12 numbers could be KITTI or EuRoC (without
    its header), and the error names both."""
    from pipeline.errors import InputError

    blocks = tmp_path / "blocks.txt"
    blocks.write_text("".join(" ".join(f"{v:.9f}," for v in row) + "\n"
                              for T in frames.T_world_lidar for row in T))
    pf = read_pose_file(blocks)
    assert pf.format == "matrix4" and pf.stamps_ns is None
    np.testing.assert_allclose(pf.T_world_x, frames.T_world_lidar, atol=1e-8)
    kitti_csv = tmp_path / "kitti.csv"
    kitti_csv.write_text("".join(",".join(f"{v:.9f}" for v in T[:3].ravel()) + "\n"
                                 for T in frames.T_world_lidar))
    with pytest.raises(InputError, match=r"12 numbers a line, comma-separated without an EuRoC "
                                         r"header could be kitti or euroc; give --poses-format "
                                         r"kitti\|euroc"):
        read_pose_file(kitti_csv)
    assert read_pose_file(kitti_csv, "kitti").T_world_x.shape == (len(frames.T_world_lidar), 4, 4)
    odd = tmp_path / "odd.txt"
    odd.write_text("1 2 3 4 5\n")
    with pytest.raises(InputError, match="cannot tell the pose format from 5 numbers a line"):
        read_pose_file(odd)


def test_every_pose_format_is_read_and_guessed(frames: KittiFrames, tmp_path: Path) -> None:
    for kind, path in pose_file_variants(frames, tmp_path).items():
        pf = read_pose_file(path)  # auto
        assert pf.format == kind.split("_")[0], kind
        np.testing.assert_allclose(pf.T_world_x, frames.T_world_lidar, atol=1e-6, err_msg=kind)
        if kind in ("kitti", "matrix4"):
            assert pf.stamps_ns is None
        else:
            np.testing.assert_array_equal(pf.stamps_ns, frames.stamps_ns + 100 * 10**9)
    bare = tmp_path / "bare.csv"  # commas, no header: w first (EuRoC) or last (TUM)?
    bare.write_text("1.0,0,0,0,0,0,0,1\n2.0,1,0,0,0,0,0,1\n")
    code, _, err = ingest(scan_folder(tmp_path, frames), "--poses", bare, "--out",
                          tmp_path / "s.mcap")
    assert code == 1 and "could be tum or euroc; give --poses-format tum|euroc" in err, err
    assert read_pose_file(bare, "tum").format == "tum"
    for fmt, path in (("tum", "tum"), ("euroc", "euroc"), ("matrix4", "matrix4_stamped")):
        variants = pose_file_variants(frames, tmp_path)
        code, _, err = ingest(scan_folder(tmp_path, frames), "--poses", variants[path],
                              "--poses-format", fmt, "--out", tmp_path / "s.mcap")
        assert code == 0, err
        with SequenceReader(tmp_path / "s.mcap") as r:
            np.testing.assert_allclose(r.ground_truth(), frames.T_world_lidar, atol=1e-6)
    code, _, err = ingest(scan_folder(tmp_path, frames), "--poses", variants["tum"],
                          "--poses-format", "kitti", "--out", tmp_path / "s.mcap")
    assert code == 1 and "expected 12 numbers (kitti pose file), got 8" in err, err


def test_extrinsic_turns_camera_poses_into_lidar_poses(frames: KittiFrames, kitti_root: Path,
                                                       tmp_path: Path,
                                                       caplog: pytest.LogCaptureFixture) -> None:
    """KITTI's camera poses without the extrinsic: one warning (motion along z); with it as 12
    numbers, 16 numbers, a file or the calib.txt: the LiDAR ground truth."""
    d = scan_folder(tmp_path, frames)
    write_kitti_poses(tmp_path / "cam.txt", frames.T_world_cam)
    out = tmp_path / "s.mcap"
    result = CliRunner().invoke(main, ["ingest", "folder", str(d), "--poses",
                                       str(tmp_path / "cam.txt"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    warnings = [r.message for r in caplog.records if "z axis" in r.message]
    assert len(warnings) == 1 and "--extrinsic" in warnings[0], caplog.text
    caplog.clear()
    Tr = frames.Tr
    twelve = " ".join(f"{v:.12e}" for v in Tr[:3].ravel())
    (tmp_path / "tr.txt").write_text(" ".join(f"{v:.12e}" for v in Tr.ravel()) + "\n")
    calib = kitti_root / "sequences" / "04" / "calib.txt"
    for extrinsic in (twelve, " ".join(f"{v:.12e}" for v in Tr.ravel()), tmp_path / "tr.txt",
                      calib):
        result = CliRunner().invoke(main, ["ingest", "folder", str(d), "--poses",
                                           str(tmp_path / "cam.txt"), "--extrinsic",
                                           str(extrinsic), "--out", str(out)])
        assert result.exit_code == 0 and "z axis" not in caplog.text, result.output
        with SequenceReader(out) as r:
            np.testing.assert_allclose(r.ground_truth(), frames.T_world_lidar, atol=1e-6)
    code, _, err = ingest(d, "--poses", tmp_path / "cam.txt", "--extrinsic", "1 2 3", "--out", out)
    assert code == 1 and "12 or 16" in err
    from pipeline.sources.poses import read_extrinsic  # comma-separated; KITTI raw's key

    np.testing.assert_allclose(read_extrinsic(twelve.replace(" ", ",")), Tr)
    (tmp_path / "raw_calib.txt").write_text(f"calib_time: 2011\nTr_velo_to_cam: {twelve}\n")
    np.testing.assert_allclose(read_extrinsic(tmp_path / "raw_calib.txt"), Tr)


def test_pcd_intensity_0_255_and_per_point_time(frames: KittiFrames, tmp_path: Path) -> None:
    """uint8 intensities are scaled to 0-1 (recorded in the metadata; --intensity keep keeps
    them); a PCD time field ``t`` becomes the scans' per-point time."""
    kf = replace(frames, points=frames.points[:3])
    d = tmp_path / "scans"
    d.mkdir()
    for k, pts in enumerate(kf.points):
        write_pcd(d / f"{k}.pcd", pts, intensity="U", time_s=point_times_s(pts))
    out = tmp_path / "s.mcap"
    code, _, err = ingest(d, "--out", out)
    assert code == 0, err
    with SequenceReader(out) as r:
        assert r.info.extra["intensity"] == "0-255 scaled to 0-1 (x 1/255)"
        scan = r[1]
    pts = kf.points[1]
    np.testing.assert_allclose(scan.points_lidar[:, 3], np.round(pts[:, 3] * 255) / 255,
                               atol=1e-6)
    np.testing.assert_array_equal(scan.time_s, point_times_s(pts))
    shown = CliRunner().invoke(main, ["info", str(out)]).stdout
    assert "intensity" in shown and "0-255 scaled to 0-1" in shown and "point time" in shown
    code, _, err = ingest(d, "--intensity", "keep", "--out", out)
    with SequenceReader(out) as r:
        assert r.info.extra["intensity"].startswith("kept as recorded")
        assert r[1].points_lidar[:, 3].max() > 1.0


def test_read_only_logging_is_one_line(caplog: pytest.LogCaptureFixture) -> None:
    """The camera-frame warning is one log line (not a traceback, not one per scan)."""
    from pipeline.sources.poses import warn_if_not_lidar_frame

    T = np.tile(np.eye(4), (20, 1, 1))
    T[:, 2, 3] = np.arange(20) * 1.0  # moving along z
    with caplog.at_level(logging.WARNING):
        assert warn_if_not_lidar_frame(T, "poses.txt")
    assert len(caplog.records) == 1 and "100 % of the motion" in caplog.records[0].message
    T[:, 2, 3], T[:, 0, 3] = 0.0, np.arange(20) * 1.0
    assert not warn_if_not_lidar_frame(T, "poses.txt")


def test_a_kitti_slice_as_pcds_with_the_full_times_poses_and_calib(frames: KittiFrames,
                                                                   kitti_root: Path,
                                                                   tmp_path: Path) -> None:
    """Frames 000004..000007 of KITTI 04 as PCD files with KITTI's own times.txt, poses/04.txt
    and calib.txt, uncut: each scan takes its own line (the issue needed hand-cut files)."""
    d = tmp_path / "slice"
    d.mkdir()
    for k in range(4, 8):
        write_pcd(d / f"{k:06d}.pcd", frames.points[k])
    seq = kitti_root / "sequences" / "04"
    out = tmp_path / "s.mcap"
    code, _, err = ingest(d, "--poses", kitti_root / "poses" / "04.txt", "--times",
                          seq / "times.txt", "--calib", seq / "calib.txt", "--out", out)
    assert code == 0, err
    with SequenceReader(out) as r:
        np.testing.assert_array_equal(r.stamps_ns, frames.stamps_ns[4:8])
        np.testing.assert_allclose(r.ground_truth(), frames.T_world_lidar[4:8], atol=1e-6)
        np.testing.assert_array_equal(r[0].points_lidar, frames.points[4])


def write_pcd_columns(path: Path, columns: dict[str, np.ndarray]) -> None:
    """A binary PCD of the named (N,) columns, each in its own dtype (f4, f8, u1, u2, u4)."""
    kinds = {"f": "F", "u": "U", "i": "I"}
    rec = np.zeros(len(next(iter(columns.values()))),
                   [(name, "<" + col.dtype.str[1:]) for name, col in columns.items()])
    for name, col in columns.items():
        rec[name] = col
    head = (f"VERSION 0.7\nFIELDS {' '.join(columns)}\n"
            f"SIZE {' '.join(str(c.dtype.itemsize) for c in columns.values())}\n"
            f"TYPE {' '.join(kinds[c.dtype.kind] for c in columns.values())}\n"
            f"COUNT {' '.join('1' for _ in columns)}\nWIDTH {len(rec)}\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(rec)}\nDATA binary\n")
    path.write_bytes(head.encode() + rec.tobytes())


@pytest.mark.parametrize("field, unit", [
    ("t", "ns"),  # Ouster: uint32 ns from the start of the sweep
    ("offset_time", "ns"),  # Livox: uint32 ns
    ("timestamp", "epoch"),  # Hesai / RoboSense: float64 s since the epoch
    ("time", "before"),  # Velodyne: float32 s relative to the stamp, negative before it
])
def test_per_point_time_in_every_unit_and_16_bit_intensity(frames: KittiFrames, tmp_path: Path,
                                                           field: str, unit: str) -> None:
    """Each driver's time field becomes float32 seconds from the scan's stamp; 16-bit
    intensities are scaled by 1/65535."""
    d = tmp_path / "scans"
    d.mkdir()
    stamps_s = ["1317000000.1", "1317000000.2"]
    expected = []
    for name, pts in zip(stamps_s, frames.points, strict=False):
        rel = point_times_s(pts).astype(np.float64)  # 0 .. 0.1 s
        if unit == "ns":
            stored: np.ndarray = np.round(rel * 1e9).astype(np.uint32)
            expected.append((stored * 1e-9).astype(np.float32))
        elif unit == "epoch":
            stored = float(name) + rel
            expected.append(rel.astype(np.float32))
        else:
            stored = (rel - 0.1).astype(np.float32)
            expected.append(stored)
        write_pcd_columns(d / f"{name}.pcd", {
            "x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2],
            "intensity": np.round(pts[:, 3] * 65535).astype(np.uint16), field: stored})
    out = tmp_path / "s.mcap"
    code, _, err = ingest(d, "--out", out)
    assert code == 0, err
    with SequenceReader(out) as r:
        assert r.info.extra["intensity"] == "0-65535 scaled to 0-1 (x 1/65535)"
        for k in range(2):
            scan = r[k]
            assert scan.time_s is not None and scan.time_s.dtype == np.float32
            np.testing.assert_allclose(scan.time_s, expected[k], atol=1e-6 if unit == "epoch"
                                       else 0.0)
            np.testing.assert_allclose(scan.points_lidar[:, 3],
                                       np.round(frames.points[k][:, 3] * 65535) / 65535,
                                       atol=1e-7)
