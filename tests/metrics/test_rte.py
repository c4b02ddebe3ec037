"""Per-start-frame RTE (the paper's y_ij) against a straightforward per-frame loop."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.evaluation_data import drifting, gt_path

from pipeline.errors import InputError
from pipeline.metrics.rte import mean_rte_pct, per_frame_rte


def loop_rte(gt: np.ndarray, est: np.ndarray, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """For every frame: walk forward until the path exceeds length_m, then E = inv(dEst) dGT."""
    n = len(gt)
    t_err, r_err = np.full(n, np.nan), np.full(n, np.nan)
    for i in range(n):
        walked = 0.0
        for j in range(i + 1, n):
            walked += float(np.linalg.norm(gt[j, :3, 3] - gt[j - 1, :3, 3]))
            if walked > length_m:
                d_gt = np.linalg.inv(gt[i]) @ gt[j]
                d_est = np.linalg.inv(est[i]) @ est[j]
                E = np.linalg.inv(d_est) @ d_gt
                t_err[i] = np.linalg.norm(E[:3, 3]) / length_m * 100.0
                cos = (np.trace(E[:3, :3]) - 1.0) / 2.0
                r_err[i] = np.arccos(np.clip(cos, -1.0, 1.0)) / length_m
                break
    return t_err, r_err


@pytest.mark.parametrize("length_m", [5.0, 12.5])
def test_per_frame_rte_equals_loop(length_m: float) -> None:
    gt = gt_path(80, step_m=0.7, stop=(20, 26), seed=3)
    est = drifting(gt, seed=5, trans_sigma=0.01, rot_sigma=0.003)
    t_err, r_err = per_frame_rte(gt, est, length_m)
    t_ref, r_ref = loop_rte(gt, est, length_m)
    assert np.array_equal(np.isnan(t_err), np.isnan(t_ref))
    assert np.isfinite(t_err).sum() > 40
    ok = np.isfinite(t_ref)
    np.testing.assert_allclose(t_err[ok], t_ref[ok], rtol=1e-9)
    np.testing.assert_allclose(r_err[ok], r_ref[ok], rtol=1e-7, atol=1e-12)
    assert mean_rte_pct(gt, est, length_m) == pytest.approx(t_ref[ok].mean(), rel=1e-9)


def test_per_frame_rte_rejects_bad_estimates() -> None:
    gt = gt_path(30, seed=1)
    with pytest.raises(InputError, match="estimate has 29 poses, ground truth has 30"):
        per_frame_rte(gt, gt[:-1], 5.0)
    est = gt.copy()
    est[7, 1, 3] = np.inf
    with pytest.raises(InputError, match="non-finite pose at frame 7"):
        per_frame_rte(gt, est, 5.0)
