"""The real-data study's figures (studies.real.summary): every ratio over all sub-trajectories
and over those both settings finished, the family geometric means, the targets."""

from __future__ import annotations

import numpy as np
import pytest

from studies.real.summary import HeldOutRun, family_metrics, run_metrics, targets

PENALTY = 1000.0


def one_run(fixed_row: list[float], baseline_row: list[float], run: str = "r") -> HeldOutRun:
    """A run of 4 start frames, each setting's 1 + 2 replica runs equal to its row."""
    rows = {"fixed": fixed_row, "baseline": baseline_row, "adaptive": fixed_row,
            "in_sample": fixed_row}
    return HeldOutRun(run, "in_a", "in_distribution",
                   {s: np.array([r, r, r], np.float64) for s, r in rows.items()},
                   floor=np.array([0.5, 0.5, 0.5, np.nan]), block=2, threshold_pct=20.0,
                   penalty_pct=PENALTY)


def test_a_ratio_is_reported_over_all_and_over_the_finished_sub_trajectories() -> None:
    run = one_run([2.0, 2.0, 4.0, np.nan], [4.0, 4.0, PENALTY, np.nan])
    m = run_metrics(run, resamples=200, confidence=0.95, seed=0)
    every = m["ratios"]["fixed_vs_baseline"]["all"]
    finished = m["ratios"]["fixed_vs_baseline"]["finished"]
    assert every["value"] == pytest.approx(8 / 1008)  # mean 8/3 over mean 1008/3
    assert every["sub_trajectories"] == 3
    assert finished["value"] == pytest.approx(0.5)  # the failed frame left out: 4 / 8
    assert finished["sub_trajectories"] == 2
    assert m["pooled"]["baseline"]["failure_rate"] == pytest.approx(1 / 3)
    assert m["floor"]["floor_vs_fixed"] == pytest.approx(0.5 / (8 / 3))


def test_the_replica_median_is_taken_per_start_frame_before_the_ratio() -> None:
    run = one_run([1.0, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 2.0])
    run.t_err["fixed"][0] = [9.0, 9.0, 9.0, 9.0]  # one replica far off: the median ignores it
    m = run_metrics(run, resamples=200, confidence=0.95, seed=0)
    assert m["ratios"]["fixed_vs_baseline"]["finished"]["value"] == pytest.approx(0.5)


def test_families_take_geometric_means_with_an_interval_from_five_runs() -> None:
    runs = [run_metrics(one_run([1.0] * 4, [b] * 4, f"r{i}"), 100, 0.95, 0)
            for i, b in enumerate([2.0, 4.0, 2.0, 4.0])]
    fam = family_metrics(runs, 0.95, 1000, 0)["fixed_vs_baseline"]["finished"]
    assert fam["geomean"] == pytest.approx(np.sqrt(0.5 * 0.25))
    assert fam["runs"] == 4 and fam["low"] is None and fam["high"] is None
    assert fam["worst"] == pytest.approx(0.5)
    runs.append(run_metrics(one_run([1.0] * 4, [2.0] * 4, "r5"), 100, 0.95, 0))
    fam = family_metrics(runs, 0.95, 1000, 0)["fixed_vs_baseline"]["finished"]
    assert fam["low"] is not None and fam["low"] <= fam["geomean"] <= fam["high"]


def test_the_targets_read_the_finished_ratios() -> None:
    run = run_metrics(one_run([1.0] * 4, [4.0] * 4), 100, 0.95, 0)
    by = {a: {"runs": [run], "families": {"in_distribution": family_metrics([run], 0.95, 100,
                                                                             0)}}
          for a in ("gicp", "ndt")}
    t = targets(by, {"fixed_vs_baseline": 0.5, "adaptive_vs_fixed_in": 0.85,
                     "adaptive_vs_fixed_out": 1.0, "worst_run": 1.1})
    assert t["tuning_pays"]["met"] and t["tuning_pays"]["per_algorithm"]["gicp"] == 0.25
    assert not t["adapting_pays_in_distribution"]["met"]  # adaptive = fixed: 1.0 > 0.85
    assert t["worst_run"]["met"]
    assert t["out_of_environment"]["per_algorithm"] == {"gicp": None, "ndt": None}
    assert not t["out_of_environment"]["met"]  # nothing measured is not a target met


def test_a_run_without_a_finished_pair_is_no_worst_case() -> None:
    measured = run_metrics(one_run([1.0] * 4, [4.0] * 4), 100, 0.95, 0)
    failed = run_metrics(one_run([PENALTY] * 4, [4.0] * 4, "r2"), 100, 0.95, 0)
    assert failed["ratios"]["adaptive_vs_fixed"]["finished"]["value"] is None
    goals = {"fixed_vs_baseline": 0.5, "adaptive_vs_fixed_in": 0.85,
             "adaptive_vs_fixed_out": 1.0, "worst_run": 1.1}
    t = targets({"ndt": {"runs": [measured, failed], "families": {}}}, goals)
    assert t["worst_run"]["per_algorithm"] == {"ndt": 1.0} and t["worst_run"]["met"]
    t = targets({"ndt": {"runs": [failed], "families": {}}}, goals)
    assert t["worst_run"]["per_algorithm"] == {"ndt": None} and not t["worst_run"]["met"]
