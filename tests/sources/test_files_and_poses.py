"""Scan-file readers (PCD ascii / binary / compressed, PLY) and pose time matching."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers.source_inputs import write_pcd, write_tum

from pipeline.errors import InputError
from pipeline.geometry import pose_from_xyz_quat, rot_z
from pipeline.posefile import read_pose_file
from pipeline.sequence import SequenceReader
from pipeline.sources import ingest_folder
from pipeline.sources.poses import interpolate_poses
from pipeline.sources.scanfiles import read_scan


@pytest.fixture
def cloud(rng: np.random.Generator) -> np.ndarray:
    pts = rng.normal(scale=20.0, size=(500, 4)).astype(np.float32)
    pts[:, 3] = rng.uniform(0, 1, 500)
    return pts


def test_pcd_binary_and_ascii(tmp_path: Path, cloud: np.ndarray) -> None:
    write_pcd(tmp_path / "b.pcd", cloud)
    write_pcd(tmp_path / "a.pcd", cloud, ascii_data=True)
    np.testing.assert_array_equal(read_scan(tmp_path / "b.pcd").points, cloud)
    np.testing.assert_array_equal(read_scan(tmp_path / "a.pcd").points, cloud)


def test_pcd_ascii_value_beyond_its_type(tmp_path: Path) -> None:
    """A value an ascii body's declared type cannot hold is refused, naming the field, without
    numpy's cast warning (1e300 in a float32 field became inf, 300 in a uint8 field wrapped)."""
    head = ("VERSION .7\nFIELDS x y z i\nSIZE 4 4 4 {size}\nTYPE F F F {type}\nCOUNT 1 1 1 1\n"
            "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n")
    for size, kind, row, rule in [("4", "F", "1 2 3 1e300", "field i holds 1e+300"),
                                  ("1", "U", "1 2 3 300", "field i holds 300"),
                                  ("1", "U", "1 2 3 nan", "field i holds nan")]:
        path = tmp_path / "v.pcd"
        path.write_text(head.format(size=size, type=kind) + "1 2 3 1\n" + row + "\n")
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(InputError, match=rf"v.pcd: PCD {re.escape(rule)}.*does not fit"):
                read_scan(path)


def test_pcd_truncated(tmp_path: Path, cloud: np.ndarray) -> None:
    write_pcd(tmp_path / "b.pcd", cloud)
    (tmp_path / "b.pcd").write_bytes((tmp_path / "b.pcd").read_bytes()[:-10])
    with pytest.raises(InputError, match=r"b.pcd: PCD data is .* truncated"):
        read_scan(tmp_path / "b.pcd")


def test_open3d_formats_ply_and_compressed_pcd(tmp_path: Path, cloud: np.ndarray) -> None:
    import open3d as o3d

    pc = o3d.t.geometry.PointCloud()
    pc.point.positions = o3d.core.Tensor(cloud[:, :3])
    pc.point.intensity = o3d.core.Tensor(cloud[:, 3:4])
    o3d.t.io.write_point_cloud(str(tmp_path / "s.ply"), pc)
    o3d.t.io.write_point_cloud(str(tmp_path / "c.pcd"), pc, write_ascii=False, compressed=True)
    assert b"binary_compressed" in (tmp_path / "c.pcd").read_bytes()[:400]
    for name in ("s.ply", "c.pcd"):
        np.testing.assert_allclose(read_scan(tmp_path / name).points, cloud, rtol=1e-6,
                                   err_msg=name)


def test_folder_without_poses_uses_the_rate(tmp_path: Path, cloud: np.ndarray) -> None:
    d = tmp_path / "scans"
    d.mkdir()
    for k in range(3):
        cloud[k : k + 1].repeat(10, 0).tofile(d / f"{k}.bin")
    report = ingest_folder(d, tmp_path / "s.mcap", rate_hz=20.0)
    assert report.frames == 3 and not report.has_ground_truth
    with SequenceReader(tmp_path / "s.mcap") as r:
        np.testing.assert_array_equal(r.stamps_ns, [0, 50_000_000, 100_000_000])
        assert r.ground_truth() is None


def test_interpolation_is_exact_at_stamps_and_slerps_between() -> None:
    stamps = np.array([0, 1_000_000, 3_000_000], np.int64)
    T = np.stack([np.eye(4)] * 3)
    for k, yaw in enumerate([0.0, 0.4, 1.2]):
        T[k, :3, :3] = rot_z(yaw)
        T[k, :3, 3] = [k * 2.0, 0, 1]
    got = interpolate_poses(np.array([1_000_000, 2_000_000, 2_500_000]), stamps, T, "t")
    np.testing.assert_allclose(got[0], T[1], atol=1e-12)
    np.testing.assert_allclose(got[1, :3, :3], rot_z(0.8), atol=1e-12)
    np.testing.assert_allclose(got[1, :3, 3], [3.0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(got[2, :3, :3], rot_z(1.0), atol=1e-12)
    with pytest.raises(InputError, match="outside the ground-truth time span"):
        interpolate_poses(np.array([4_000_000_000]), stamps, T, "t")


def test_tum_stamps_are_exact_at_epoch_times(tmp_path: Path) -> None:
    stamps = np.array([1_700_000_000_123_456_789, 1_700_000_000_223_456_789], np.int64)
    T = pose_from_xyz_quat(np.array([[1.0, 2, 3], [4, 5, 6]]), np.array([[0, 0, 0, 1.0]] * 2))
    write_tum(tmp_path / "p.txt", stamps, T)
    pf = read_pose_file(tmp_path / "p.txt")
    assert pf.format == "tum"
    np.testing.assert_array_equal(pf.stamps_ns, stamps)
    np.testing.assert_allclose(pf.T_world_x, T)


def test_pose_file_with_a_bad_line(tmp_path: Path) -> None:
    (tmp_path / "p.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0\n")
    with pytest.raises(
        InputError, match=r"p.txt line 2: expected 12 numbers \(kitti pose file\), got 7"
    ):
        read_pose_file(tmp_path / "p.txt")
