"""`adaptune realism` end to end on real KITTI (docs/design.md, "The sim-to-real comparison"):
one slice of 4 frames, one simulated world; what it writes, and its one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from pipeline.sim import kitti_sensor


def adaptune(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "stages.cli", *map(str, args)],
                          capture_output=True, text=True)


def test_realism_compares_a_real_slice_with_its_simulation(tmp_path: Path, kitti_root: Path,
                                                           kitti_trajectories: Path) -> None:
    out = tmp_path / "realism"
    done = adaptune("realism", "--kitti-root", kitti_root, "--trajectories", kitti_trajectories,
                    "--slice", "04:2:5", "--replicas", "1", "--out", out)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines()[-1].startswith(f"{out / 'realism.md'}: ")
    assert done.stderr.splitlines()[-1].endswith(" of 8 figures within x1.5 (simulated / real)")
    summary = json.loads((out / "realism.json").read_text())
    assert (summary["replicas"], summary["sensor"], summary["beams"]) == (1, "hdl64", 64)
    (slice_,) = summary["slices"]
    assert (slice_["sequence"], slice_["first"], slice_["last"]) == ("04", 2, 5)
    # the real side is KITTI's own scans 2-5: their mean point count, 64 rings each
    bins = sorted((kitti_root / "sequences" / "04" / "velodyne").glob("*.bin"))[2:6]
    counts = [np.fromfile(b, np.float32).size // 4 for b in bins]
    assert slice_["real_stats"]["points"] == np.mean(counts)
    assert slice_["real_stats"]["rings_found"] == 64
    assert 0 < slice_["sim_stats"]["points"] < 64 * kitti_sensor.FIRINGS
    for stats in (slice_["real_stats"], slice_["sim_stats"]):
        assert 0.0 < stats["road_planarity_mm"] < 50.0
    for algorithm in ("gicp", "kiss_icp"):
        # sim: against the exact ground truth; sim_gt: with the slice's ground-truth error
        for side in ("real", "sim", "sim_gt"):
            errors = slice_[side][algorithm]
            assert len(errors["t_cm"]) == len(errors["r_deg"]) == 3  # 4 frames, 3 steps
            assert all(np.isfinite(errors["t_cm"])) and all(v >= 0 for v in errors["t_cm"])
        assert slice_["sim_gt"][algorithm] != slice_["sim"][algorithm]
    assert len(slice_["gt_error"]["mean"]) == len(slice_["gt_error"]["variance"]) == 6
    for ratios in (summary["ratios"], summary["ratios_exact_gt"]):
        assert set(ratios) == {f"{a} {what}" for a in ("gicp", "kiss_icp") for what in (
            "04 median t", "04 median r", "pooled p90 t", "pooled p90 r")}
    table = (out / "realism.md").read_text()
    assert "| 04 2-5 | rural | gicp |" in table and "| 04 2-5 | rural | kiss_icp |" in table
    assert "with the ground-truth error added" in table
    assert (out / "realism.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_slice_of_a_sequence_without_a_schedule_is_one_line_and_exit_1(
        tmp_path: Path, kitti_root: Path, kitti_trajectories: Path) -> None:
    done = adaptune("realism", "--kitti-root", kitti_root, "--trajectories", kitti_trajectories,
                    "--slice", "12:0:3", "--out", tmp_path / "r")
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "adaptune: error: no environment schedule for KITTI sequence '12' (known: "
        + ", ".join(f"{k:02d}" for k in range(11)) + ")"]
    assert not (tmp_path / "r").exists()
