"""Real KITTI odometry sequences through `adaptune ingest kitti` and `adaptune info`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from helpers.source_inputs import load_kitti

from pipeline.sequence import SequenceReader
from schemas import SCHEMA_VERSION
from stages.cli import main


@pytest.mark.parametrize("seq", ["01", "04", "06", "10"])
def test_ingest_real_kitti_sequence(seq: str, kitti_root: Path, tmp_path: Path) -> None:
    out = tmp_path / f"{seq}.mcap"
    result = CliRunner().invoke(main, ["ingest", "kitti", str(kitti_root), seq, "--out", str(out)])
    assert result.exit_code == 0, result.output
    kf = load_kitti(kitti_root, seq)
    raw0 = np.fromfile(kf.bins[0], np.float32).reshape(-1, 4)
    finite0 = int(np.isfinite(raw0[:, :3]).all(axis=1).sum())
    with SequenceReader(out) as r:
        assert len(r) == 10
        scan0 = r[0]
        assert len(scan0.points_lidar) == kf.bins[0].stat().st_size // 16 - (len(raw0) - finite0)
        np.testing.assert_array_equal(scan0.points_lidar, raw0)
        np.testing.assert_array_equal(r.stamps_ns, kf.stamps_ns)
        # ground truth in the lidar frame: inv(Tr) @ P @ Tr of the pose file
        # KITTI rotations are orthonormal to ~1e-7 only; PoseStamped keeps a unit quaternion
        np.testing.assert_allclose(r.ground_truth(), kf.T_world_lidar, atol=1e-6)
        assert r.info.sensor == "velodyne_hdl64e" and r.info.source == f"kitti:{seq}"
        # named as KITTI (and a data set, index.json) names it; the root stored absolute
        assert r.info.name == seq and r.info.extra["kitti_root"] == str(kitti_root.resolve())


def ingest_06(kitti_root: Path, out: Path, start: int, end: int) -> Result:
    """``adaptune ingest kitti ROOT 06 --out OUT --start START --end END``."""
    args = ["ingest", "kitti", str(kitti_root), "06", "--out", str(out)]
    return CliRunner().invoke(main, [*args, "--start", str(start), "--end", str(end)])


def test_start_end_pick_an_inclusive_frame_range(kitti_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "part.mcap"
    result = ingest_06(kitti_root, out, 2, 4)
    assert result.exit_code == 0, result.output
    kf = load_kitti(kitti_root, "06")
    with SequenceReader(out) as r:
        assert len(r) == 3
        np.testing.assert_array_equal(r.stamps_ns, kf.stamps_ns[2:5])
        np.testing.assert_array_equal(r[0].points_lidar, kf.points[2])
        np.testing.assert_allclose(r.ground_truth(), kf.T_world_lidar[2:5], atol=1e-6)


def test_start_end_out_of_range_is_an_error(kitti_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "bad.mcap"
    result = ingest_06(kitti_root, out, 5, 10)
    assert result.exit_code == 1
    assert "--end 10 is not within 0..9" in result.stderr
    assert not out.exists()


def test_info_json_and_table(kitti_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "04.mcap"
    runner = CliRunner()
    assert (
        runner.invoke(
            main, ["ingest", "kitti", str(kitti_root), "04", "--out", str(out), "--end", "4"]
        ).exit_code
        == 0
    )
    result = runner.invoke(main, ["info", str(out), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    kf = load_kitti(kitti_root, "04", 5)
    sizes = [len(p) for p in kf.points]
    assert info["frames"] == 5 and info["has_ground_truth"] is True
    assert info["duration_s"] == pytest.approx((kf.stamps_ns[4] - kf.stamps_ns[0]) / 1e9)
    steps = np.linalg.norm(np.diff(kf.T_world_lidar[:, :3, 3], axis=0), axis=1)
    assert info["path_length_m"] == pytest.approx(steps.sum(), abs=1e-6)
    assert info["points_per_scan"] == {
        "min": min(sizes),
        "median": float(np.median(sizes)),
        "max": max(sizes),
    }
    assert info["sensor"] == "velodyne_hdl64e" and info["labels"] == []
    assert info["schema_version"] == SCHEMA_VERSION
    table = runner.invoke(main, ["info", str(out)])
    assert table.exit_code == 0 and "frames" in table.stdout and "velodyne_hdl64e" in table.stdout
