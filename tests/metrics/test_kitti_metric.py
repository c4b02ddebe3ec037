"""The KITTI devkit metric: against kiss-icp's C++ port, a literal transcription, hand cases."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.evaluation_data import cli_fails, drifting

from pipeline.metrics.kitti import LENGTHS_M, kitti_errors, kitti_sequence_error
from pipeline.posefile import read_kitti_poses, write_kitti_poses
from stages.cli import main

FLOAT32_RTOL = 2.0**-23  # kiss-icp returns std::tuple<float, float>: one float32 rounding


def devkit_loop(gt: np.ndarray, est: np.ndarray, lengths: tuple[float, ...] = LENGTHS_M,
                step: int = 10) -> list[tuple[int, float, float, float]]:
    """calcSequenceErrors of evaluate_odometry.cpp, transcribed line by line (its lengths and
    step as arguments)."""
    dist = [0.0]
    for i in range(1, len(gt)):
        dx, dy, dz = gt[i - 1][:3, 3] - gt[i][:3, 3]
        dist.append(dist[i - 1] + np.sqrt(dx * dx + dy * dy + dz * dz))
    err = []
    for first in range(0, len(gt), step):
        for length in lengths:
            last = next((i for i in range(first, len(dist)) if dist[i] > dist[first] + length), -1)
            if last == -1:
                continue
            d_gt = np.linalg.inv(gt[first]) @ gt[last]
            d_est = np.linalg.inv(est[first]) @ est[last]
            E = np.linalg.inv(d_est) @ d_gt
            a, b, c = E[0, 0], E[1, 1], E[2, 2]
            r = np.arccos(max(min(0.5 * (a + b + c - 1.0), 1.0), -1.0))
            t = np.sqrt(E[0, 3] ** 2 + E[1, 3] ** 2 + E[2, 3] ** 2)
            err.append((first, r / length, t / length, length))
    return err


@pytest.mark.parametrize("seq", ["03", "07"])
def test_matches_kiss_icp_port(kitti_trajectories: Path, seq: str) -> None:
    from kiss_icp.metrics import sequence_error

    gt = read_kitti_poses(kitti_trajectories / f"{seq}.txt")
    est = drifting(gt, seed=int(seq), trans_sigma=0.01, rot_sigma=5e-4, scale=1.003)
    t_pct, r_deg = kitti_sequence_error(gt, est)
    t_ref, r_ref = sequence_error(gt, est)
    assert t_pct > 0.1
    assert t_pct == pytest.approx(t_ref, rel=FLOAT32_RTOL, abs=0)
    # the port converts rad to deg with 180 / 3.14 (not pi); undo that to compare
    assert np.radians(r_deg) * 180.0 / 3.14 == pytest.approx(r_ref, rel=FLOAT32_RTOL, abs=0)


def test_every_segment_matches_devkit_transcription(kitti_trajectories: Path) -> None:
    gt = read_kitti_poses(kitti_trajectories / "04.txt")
    est = drifting(gt, seed=4, trans_sigma=0.01, rot_sigma=5e-4)
    ref = devkit_loop(gt, est)
    seg = kitti_errors(gt, est)
    assert len(seg) == len(ref) > 10
    assert np.array_equal(seg.first_frame, [e[0] for e in ref])
    assert np.array_equal(seg.length_m, [e[3] for e in ref])
    np.testing.assert_allclose(seg.r_err, [e[1] for e in ref], rtol=1e-9, atol=0)
    np.testing.assert_allclose(seg.t_err, [e[2] for e in ref], rtol=1e-9, atol=0)
    t_pct, _ = kitti_sequence_error(gt, est)
    assert t_pct == pytest.approx(100 * np.mean([e[2] for e in ref]), rel=1e-12)


def test_perfect_trajectory_is_zero(kitti_trajectories: Path) -> None:
    gt = read_kitti_poses(kitti_trajectories / "04.txt")
    seg = kitti_errors(gt, gt.copy())
    assert len(seg) > 0
    assert seg.t_err.max() < 1e-12
    assert seg.r_err.max() < 1e-9  # arccos near 1: rounding noise only


def straight(n: int, step_m: float, scale: float = 1.0) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 0, 3] = np.arange(n) * step_m * scale
    return T


def test_constant_one_percent_scale_error_is_one_percent() -> None:
    gt, est = straight(20001, 0.05), straight(20001, 0.05, 1.01)
    seg = kitti_errors(gt, est)
    dist = np.arange(20001) * 0.05
    # exactly: 1 % of the true segment length, which overshoots `length` by < one step
    expected = 0.01 * (dist[seg.last_frame] - dist[seg.first_frame]) / seg.length_m
    np.testing.assert_allclose(seg.t_err, expected, rtol=1e-9)
    assert seg.t_err_pct == pytest.approx(1.0, rel=1e-3)
    assert seg.r_err_deg_per_m == 0.0


def test_segment_ends_strictly_beyond_length() -> None:
    gt = straight(2001, 0.5)  # 100 m reached exactly at frame i + 200: the end is i + 201
    seg = kitti_errors(gt, gt)
    m = seg.length_m == 100.0
    assert np.all(seg.last_frame[m] - seg.first_frame[m] == 201)


def test_pose_files_round_trip(tmp_path: Path, kitti_trajectories: Path) -> None:
    gt = read_kitti_poses(kitti_trajectories / "04.txt")
    write_kitti_poses(tmp_path / "p.txt", gt)
    np.testing.assert_allclose(read_kitti_poses(tmp_path / "p.txt"), gt, rtol=0, atol=1e-12)


def test_metric_cli_json(tmp_path: Path, kitti_trajectories: Path) -> None:
    gt_path = kitti_trajectories / "04.txt"
    gt = read_kitti_poses(gt_path)
    est = drifting(gt, seed=1, scale=1.01)
    write_kitti_poses(tmp_path / "est.txt", est)
    result = CliRunner().invoke(main, ["metric", "kitti", str(gt_path), str(tmp_path / "est.txt"),
                                       "--json"])
    assert result.exit_code == 0, result.output
    got = json.loads(result.output)
    seg = kitti_errors(gt, read_kitti_poses(tmp_path / "est.txt"))
    assert got["segments"] == len(seg)
    assert got["t_err_pct"] == pytest.approx(seg.t_err_pct, rel=1e-12)
    assert got["r_err_deg_per_m"] == pytest.approx(seg.r_err_deg_per_m, rel=1e-12)
    assert set(got["per_length"]) <= {f"{x:g}" for x in LENGTHS_M}


def test_metric_cli_bad_inputs(tmp_path: Path, kitti_trajectories: Path) -> None:
    gt_path = kitti_trajectories / "04.txt"
    gt = read_kitti_poses(gt_path)
    write_kitti_poses(tmp_path / "short.txt", gt[:-5])
    cli_fails(["metric", "kitti", str(gt_path), str(tmp_path / "short.txt")],
           "short.txt", f"{len(gt) - 5} poses", f"has {len(gt)}")
    nan = gt.copy()
    nan[100, 0, 3] = np.nan
    write_kitti_poses(tmp_path / "nan.txt", nan)
    cli_fails(["metric", "kitti", str(gt_path), str(tmp_path / "nan.txt")], "nan.txt line 101",
              "not finite")
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    cli_fails(["metric", "kitti", str(gt_path), str(tmp_path / "bad.txt")], "bad.txt line 1",
              "expected 12")
    cli_fails(["metric", "kitti", str(gt_path), str(tmp_path / "missing.txt")], "missing.txt")


def test_short_runs_score_with_short_lengths(tmp_path: Path, kitti_trajectories: Path) -> None:
    """A 60 m run has no 100 m segment: the default lengths refuse it (naming --lengths), and
    --lengths 5,10,20 --step-frames 2 (or a params file's devkit section) scores it as the
    transcribed devkit does with those lengths."""
    gt = read_kitti_poses(kitti_trajectories / "04.txt")[:60]
    est = drifting(gt, seed=2, scale=1.01)
    write_kitti_poses(tmp_path / "gt.txt", gt)
    write_kitti_poses(tmp_path / "est.txt", est)
    args = ["metric", "kitti", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt")]
    cli_fails(args, "too short for a 100 m segment", "--lengths")
    got = json.loads(CliRunner().invoke(main, [*args, "--lengths", "20,5,10", "--step-frames",
                                               "2", "--json"]).stdout)
    ref = devkit_loop(read_kitti_poses(tmp_path / "gt.txt"),
                      read_kitti_poses(tmp_path / "est.txt"), (5.0, 10.0, 20.0), 2)
    assert got["segments"] == len(ref) > 40
    assert got["t_err_pct"] == pytest.approx(100 * np.mean([e[2] for e in ref]), rel=1e-9)
    assert got["r_err_deg_per_m"] == pytest.approx(np.degrees(np.mean([e[1] for e in ref])),
                                                   rel=1e-9)
    assert list(got["per_length"]) == ["5", "10", "20"]
    (tmp_path / "params.yaml").write_text("devkit:\n  lengths_m: [5, 10, 20]\n"
                                          "  step_frames: 2\n")
    from_params = json.loads(CliRunner().invoke(
        main, [*args, "--params", str(tmp_path / "params.yaml"), "--json"]).stdout)
    assert from_params == got
    cli_fails([*args, "--lengths", "10,10"], "devkit.lengths_m", "listed twice")
    cli_fails([*args, "--lengths", "ten"], "--lengths must be metres")
