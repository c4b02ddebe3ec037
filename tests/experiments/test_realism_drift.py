"""experiments/realism_drift.py: its figures on hand-made trajectories (a step error every step
shares adds up over the slice, alternating ones cancel), and a small run: GICP on the first 5
frames of the real 04 slice and of one simulated replica."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "experiments" / "realism_drift.py"


def test_a_small_run(test_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    load_script(SCRIPT).main(["--params", str(ROOT / "params.yaml"), "--data", str(test_data),
                              "--slice", "04:0:4", "--replicas", "1", "--algorithms", "gicp"])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "| slice | algorithm | side | step [%] | bias [%] | drift [%] |"
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]
    assert [r[:3] for r in rows] == [["04 0-4", "gicp", "real"], ["04 0-4", "gicp", "sim 0"]]
    figures = [tuple(map(float, row[3:])) for row in rows]
    assert all(math.isfinite(v) and v >= 0 for f in figures for v in f), rows
    assert figures[0] != figures[1]  # the real scans and the simulated ones


def _path(steps: np.ndarray) -> np.ndarray:
    """(N + 1, 4, 4) poses from the origin along translation steps (N, 3) [m], no rotation."""
    T = np.tile(np.eye(4), (len(steps) + 1, 1, 1))
    T[1:, :3, 3] = np.cumsum(steps, axis=0)
    return T


def test_a_shared_step_error_drifts_in_full_and_alternating_ones_cancel() -> None:
    drift_figures = load_script(SCRIPT).drift_figures
    truth = _path(np.tile([1.0, 0.0, 0.0], (9, 1)))  # 9 steps of 1 m
    long = _path(np.tile([1.01, 0.0, 0.0], (9, 1)))  # every step 1 cm too long
    assert drift_figures(truth, long) == pytest.approx((1.0, 1.0, 1.0))
    side = np.array([[1.0, 0.01 * (-1) ** k, 0.0] for k in range(9)])  # +-1 cm sideways
    step, bias, drift = drift_figures(truth, _path(side))
    assert step == pytest.approx(1.0)
    assert bias == pytest.approx(100 * 0.01 / 9)  # five +1 cm, four -1 cm: 1 cm / 9 a step
    assert drift == pytest.approx(100 * 0.01 / 9)  # 1 cm over the 9 m
