"""`adaptune metric rte`: RTE of any length, and APE / RPE checked against evo itself."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from pipeline.metrics.rte import per_frame_rte
from pipeline.posefile import read_kitti_poses, write_kitti_poses, write_tum
from stages.cli import main


def noisy_estimate(gt: np.ndarray, scale: float, seed: int = 3) -> np.ndarray:
    """``gt`` with a random walk of small rotation and translation errors, scaled, seen from
    another world frame (so alignment matters)."""
    rng = np.random.default_rng(seed)
    steps = np.linalg.inv(gt[:-1]) @ gt[1:]
    est = [np.eye(4)]
    for step in steps:
        noise = np.eye(4)
        noise[:3, :3] = Rotation.from_rotvec(rng.normal(0, 2e-3, 3)).as_matrix()
        noise[:3, 3] = rng.normal(0, 0.02, 3)
        est.append(est[-1] @ step @ noise)
    out = np.array(est)
    out[:, :3, 3] *= scale
    world = np.eye(4)
    world[:3, :3] = Rotation.from_euler("zyx", [0.7, 0.1, -0.2]).as_matrix()
    world[:3, 3] = [5.0, -3.0, 2.0]
    return world @ out


def run_json(args: list[str]) -> dict:
    result = CliRunner().invoke(main, [*args, "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


@pytest.mark.parametrize("scale", [False, True])
def test_ape_and_rpe_match_evo(kitti_trajectories: Path, tmp_path: Path, scale: bool) -> None:
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D
    from evo.core.units import Unit

    gt = read_kitti_poses(kitti_trajectories / "04.txt")[:120]
    est = noisy_estimate(gt, 1.3 if scale else 1.0)
    write_kitti_poses(tmp_path / "gt.txt", gt)
    write_kitti_poses(tmp_path / "est.txt", est)
    args = ["metric", "rte", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt"),
            "--length", "20"]
    got = run_json([*args, "--scale"] if scale else args)
    ref, path = PosePath3D(poses_se3=list(gt)), PosePath3D(poses_se3=list(est))
    path.align(ref, correct_scale=scale)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, path))
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1, delta_unit=Unit.frames)
    rpe.process_data((ref, path))
    for ours, theirs in ((got["ape"], ape.get_all_statistics()),
                         (got["rpe"], rpe.get_all_statistics())):
        for key in ("rmse", "mean", "median", "std", "min", "max"):
            assert ours[key] == pytest.approx(theirs[key], rel=1e-6, abs=1e-9), key
    assert got["ape"]["scale"] == pytest.approx(1 / 1.3 if scale else 1.0, rel=0.05)
    t_err, _ = per_frame_rte(gt, est, 20.0)
    assert got["rte"]["t_err_pct"] == pytest.approx(np.nanmean(t_err), rel=1e-9)
    assert got["rte"]["segments"] == int(np.isfinite(t_err).sum())


def test_short_runs_and_stamped_formats(kitti_trajectories: Path, tmp_path: Path) -> None:
    """A 15 m run (too short for `metric kitti`) scores with L = 5 m; a TUM estimate pairs
    with a TUM ground truth by time; the table names the three errors."""
    gt = read_kitti_poses(kitti_trajectories / "04.txt")[:12]
    stamps = 100.0 + 0.1 * np.arange(12)
    write_tum(tmp_path / "gt.tum", stamps, gt)
    write_tum(tmp_path / "est.tum", stamps[2:] + 0.002, noisy_estimate(gt, 1.0)[2:])
    result = CliRunner().invoke(main, ["metric", "rte", str(tmp_path / "gt.tum"),
                                       str(tmp_path / "est.tum"), "--length", "5"])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("10 frames") and lines[1].startswith("RTE  L = 5 m")
    assert lines[2].startswith("APE  se3 Umeyama") and lines[3].startswith("RPE  1 frame")
    long = CliRunner().invoke(main, ["metric", "rte", str(tmp_path / "gt.tum"),
                                     str(tmp_path / "est.tum"), "--length", "500"])
    assert long.exit_code == 1 and "not longer than --length 500 m" in long.stderr
