"""The real-data study's figures (``metrics/real.json``), from every fold's suite.

Per test run of a fold (its units' start frames pooled): every setting's RTE per start frame
is the median over its runs (the nominal one and the replicas); a ratio of two settings is the
ratio of their mean RTE over the run's start frames, with a moving-block bootstrap interval
over the start frames (blocks of the frames a sub-trajectory spans,
``studies.suites.statistics.block_ratio``). Every ratio twice: over all sub-trajectories, a
failed run's at the penalty, and over those where both settings finished (neither at the
penalty). Per family and algorithm: the geometric mean of the runs' ratios over the family's
folds, with scipy's BCa interval over runs where there are at least five. Per algorithm and
run: the pooled RTE and the failure rate of every setting (a sub-trajectory whose RTE exceeds
the length's threshold fails). The reference's floor: the SLAM system's own odometry scored
the same way, as a ratio to each setting (a lower bound, not a competitor).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from studies.suites.statistics import block_ratio, pooled, ratio_estimate

F64 = NDArray[np.float64]
SETTINGS = ("baseline", "fixed", "adaptive", "in_sample")
RATIOS = {"fixed_vs_baseline": ("fixed", "baseline"),
          "adaptive_vs_fixed": ("adaptive", "fixed"),
          "adaptive_vs_baseline": ("adaptive", "baseline"),
          "adaptive_vs_in_sample": ("adaptive", "in_sample"),
          "fixed_vs_in_sample": ("fixed", "in_sample")}
"""The ratios of every run: name -> (numerator, denominator)."""
MIN_RUNS_FOR_INTERVAL = 5


class HeldOutRun:
    """One test run of one fold: per setting, (R + 1, N) RTE [%] of its units' start frames
    pooled, the floor's (N,), the frames a sub-trajectory spans (the bootstrap's block) and
    the failure threshold and penalty [%]."""

    def __init__(self, run: str, fold: str, family: str, t_err: Mapping[str, F64],
                 floor: F64, block: int, threshold_pct: float, penalty_pct: float) -> None:
        self.run, self.fold, self.family = run, fold, family
        self.t_err = {s: np.asarray(v, np.float64) for s, v in t_err.items()}
        self.floor = np.asarray(floor, np.float64)
        self.block, self.threshold_pct, self.penalty_pct = block, threshold_pct, penalty_pct

    def medians(self, setting: str) -> F64:
        """(N,) the median over the setting's runs of every start frame (NaN: none scored)."""
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                return np.nanmedian(self.t_err[setting], axis=0)  # type: ignore[no-any-return]

    def ratio(self, num: str, den: str, finished_only: bool, resamples: int,
              confidence: float, seed: int) -> dict[str, Any]:
        """``num`` / ``den`` over the run's start frames (module docstring)."""
        a, b = self.medians(num), self.medians(den)
        keep = np.isfinite(a) & np.isfinite(b)
        if finished_only:
            keep &= (a < self.penalty_pct) & (b < self.penalty_pct)
        est = block_ratio(a[keep], b[keep], self.block, resamples, confidence, seed)
        return {**est.to_json(), "sub_trajectories": int(keep.sum())}

    def floor_ratio(self, setting: str) -> float | None:
        """floor / setting over the start frames both scored: how much of the setting's RTE
        the reference's own error could explain."""
        a, b = self.floor, self.medians(setting)
        keep = np.isfinite(a) & np.isfinite(b)
        return float(a[keep].mean() / b[keep].mean()) if keep.any() and b[keep].mean() > 0 \
            else None


def run_metrics(run: HeldOutRun, resamples: int, confidence: float, seed: int) -> dict[str, Any]:
    """One test run's figures: every ratio both ways, the pooled RTE and failure rate of every
    setting, the floor."""
    settings = [s for s in SETTINGS if s in run.t_err]
    ratios = {name: {"all": run.ratio(n, d, False, resamples, confidence, seed),
                     "finished": run.ratio(n, d, True, resamples, confidence, seed)}
              for name, (n, d) in RATIOS.items() if n in run.t_err and d in run.t_err}
    return {"run": run.run, "fold": run.fold, "family": run.family, "block_frames": run.block,
            "ratios": ratios,
            "pooled": {s: pooled([run.t_err[s]], run.threshold_pct) for s in settings},
            "floor": {"rte_pct": pooled([run.floor], run.threshold_pct)["rte_pct"],
                      **{f"floor_vs_{s}": run.floor_ratio(s) for s in settings}}}


def family_metrics(runs: Sequence[dict[str, Any]], confidence: float, resamples: int,
                   seed: int) -> dict[str, Any]:
    """Per ratio and way (all, finished): the geometric mean of the runs' ratios with its BCa
    interval over runs (at least ``MIN_RUNS_FOR_INTERVAL``), the worst run and the count."""
    out: dict[str, Any] = {}
    for name in RATIOS:
        for way in ("all", "finished"):
            values = [r["ratios"][name][way]["value"] for r in runs if name in r["ratios"]]
            v = np.array([x for x in values if x is not None], np.float64)
            est = ratio_estimate(v, confidence, resamples, seed)
            interval = len(v) >= MIN_RUNS_FOR_INTERVAL
            out.setdefault(name, {})[way] = {
                "geomean": est.value, "low": est.low if interval else None,
                "high": est.high if interval else None, "runs": len(v),
                "worst": float(v.max()) if len(v) else None}
    return out


def targets(by_algorithm: Mapping[str, Mapping[str, Any]],
            goals: Mapping[str, float]) -> dict[str, Any]:
    """The study's targets (``goals``: params ``real.targets``) against the figures, over the
    sub-trajectories both settings finished: fixed / baseline in distribution per algorithm;
    adaptive / fixed in distribution (at least two algorithms); out of environment; the worst
    single run. A target whose figure nothing measured (no sub-trajectory both settings
    finished: None) is not met."""
    def fam(a: str, family: str, name: str) -> float | None:
        return by_algorithm[a]["families"].get(family, {}).get(name, {}).get(
            "finished", {}).get("geomean")

    algorithms = list(by_algorithm)
    tuning = {a: fam(a, "in_distribution", "fixed_vs_baseline") for a in algorithms}
    adapt = {a: fam(a, "in_distribution", "adaptive_vs_fixed") for a in algorithms}
    ooe = {a: fam(a, "out_of_environment", "adaptive_vs_fixed") for a in algorithms}
    worst = {a: max((v for r in by_algorithm[a]["runs"]
                     if (v := r["ratios"]["adaptive_vs_fixed"]["finished"]["value"])
                     is not None), default=None) for a in algorithms}

    def met(v: float | None, at_most: float) -> bool:  # a figure nothing measured is not met
        return v is not None and v <= at_most

    return {
        "tuning_pays": {"at_most": goals["fixed_vs_baseline"], "per_algorithm": tuning,
                        "met": all(met(v, goals["fixed_vs_baseline"]) for v in tuning.values())},
        "adapting_pays_in_distribution": {
            "at_most": goals["adaptive_vs_fixed_in"], "per_algorithm": adapt,
            "met": sum(met(v, goals["adaptive_vs_fixed_in"]) for v in adapt.values()) >= 2},
        "out_of_environment": {"at_most": goals["adaptive_vs_fixed_out"], "per_algorithm": ooe,
                               "met": all(met(v, goals["adaptive_vs_fixed_out"])
                                          for v in ooe.values())},
        "worst_run": {"at_most": goals["worst_run"], "per_algorithm": worst,
                      "met": all(met(v, goals["worst_run"]) for v in worst.values())},
    }
