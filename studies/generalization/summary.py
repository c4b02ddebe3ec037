"""The suite's figures: per-world ratios and their median, worst world, win rate and a
bootstrap interval of the median, and the verdict on the suite's targets (``targets_met`` of
adaptive / min(baseline, fixed)) (``metrics/generalization.json``, ``plots/generalization.csv``;
``records/generalization.json`` holds the rest of the summary: ``RECORD_KEYS``).

A ratio below 1 means adaptive beat the other setting on that world (lower RTE); the win rate
is the fraction of worlds whose ratio is below 1. The interval is the percentile bootstrap
(worlds resampled with replacement, ``resamples`` times, seeded) of the median ratio.

``geometric``: the verdict's statistics of every ratio (the ratios of the settings' medians
over their runs with replicas): geometric mean with its 95 % BCa bootstrap interval, win rate
with its Wilson interval (``studies.suites.statistics``; docs/results/verdict-protocol.md).

With replicas (``pipeline.evaluate.replicas``) two more blocks: ``replica_summary``, the
same figures of the ratios of every setting's median over its runs, and ``noise``, how far
runs of one setting are from each other on a world: per setting the median over worlds of the
coefficient of variation of its runs, and over the ordered pairs of two runs of baseline or of
fixed on one world, the fraction whose ratio exceeds the worst-world target
(``chance_above_worst_target``) and the 95th percentile of that ratio (``chance_ratio_p95``):
the ratios a selector no better and no worse than a fixed setting would show by chance.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from studies.generalization.score import WorldScore

RATIOS = ("adaptive_vs_best", "adaptive_vs_baseline", "adaptive_vs_fixed")
RECORD_KEYS = ("seed_root", "length_m", "worlds", "frames", "replicas", "seed", "wall_time_s",
               "replicas_rte_pct", "targets")
"""The summary's bookkeeping (besides its text: names, segments, sensors): the suite's seeds
and sizes, L, wall times and the replica runs' raw lists."""
PLOT_COLUMNS = ("world", "segments", "sensor", "frames", "baseline_pct", "fixed_pct",
                "adaptive_pct", *RATIOS)
"""The columns of ``generalization_rows`` without replicas (the header of a suite without
worlds)."""
INTERVAL = 0.90
"""The level of the median's bootstrap interval."""


def meets_targets(summary: Mapping[str, Any], targets: Mapping[str, float]) -> bool | None:
    """The verdict: whether a ``median_summary`` of adaptive / min(baseline, fixed) meets the
    three ``targets`` (params ``generalize.targets``; None without a finite ratio)."""
    if summary["median"] is None:
        return None
    return bool(summary["median"] <= targets["median"] and summary["worst"] <= targets["worst"]
                and summary["win_rate"] >= targets["win_rate"])


def median_summary(names: Sequence[str], ratios: Sequence[float], resamples: int,
                  seed: int) -> dict[str, Any]:
    """median, worst (largest) ratio and its world, win rate, bootstrap interval of the
    median (``INTERVAL``) of one ratio over the worlds (NaN ratios left out)."""
    r = np.asarray(ratios, np.float64)
    ok = np.isfinite(r)
    if not ok.any():
        return {"median": None, "worst": None, "worst_world": None, "win_rate": None,
                "median_interval": [None, None], "worlds": 0}
    r_ok = r[ok]
    rng = np.random.default_rng([seed, len(r_ok)])
    medians = np.median(rng.choice(r_ok, (resamples, len(r_ok)), replace=True), axis=1)
    lo, hi = np.quantile(medians, [(1 - INTERVAL) / 2, (1 + INTERVAL) / 2])
    worst = int(np.flatnonzero(ok)[np.argmax(r_ok)])
    return {"median": float(np.median(r_ok)), "worst": float(r[worst]),
            "worst_world": names[worst], "win_rate": float((r_ok < 1.0).mean()),
            "median_interval": [float(lo), float(hi)], "worlds": int(ok.sum())}


def generalization_metrics(scores: Sequence[WorldScore], suite: str, root: int, resamples: int,
                           algorithm: str, length_m: float,
                           targets: Mapping[str, float]) -> dict[str, Any]:
    """The summary of the suite, every world, every ratio, against ``targets`` (module
    docstring)."""
    names = [s.name for s in scores]
    summary = {k: median_summary(names, [s.ratios()[k] for s in scores], resamples, root)
               for k in RATIOS}
    summary["adaptive_vs_best"]["targets_met"] = meets_targets(summary["adaptive_vs_best"],
                                                               targets)
    out: dict[str, Any] = {
        "algorithm": algorithm,
        "suite": suite,
        "seed_root": root,
        "length_m": length_m,
        "worlds": len(scores),
        "frames": sum(s.frames for s in scores),
        "summary": summary,
        "targets": dict(targets),
    }
    replicas = any(s.replicas_rte_pct for s in scores)
    if replicas:
        out["replicas"] = max(len(v) for s in scores for v in s.replicas_rte_pct.values())
        out["replica_summary"] = {
            k: median_summary(names, [s.replica_ratios()[k] for s in scores], resamples, root)
            for k in RATIOS}
        best = out["replica_summary"]["adaptive_vs_best"]
        best["targets_met"] = meets_targets(best, targets)
        out["noise"] = noise_summary(scores, targets["worst"])
    out["geometric"] = {k: geometric_summary([(s.replica_ratios() if replicas
                                               else s.ratios())[k] for s in scores], root)
                        for k in RATIOS}
    out["per_world"] = {s.name: s.to_json() for s in scores}
    return out


def geometric_summary(ratios: Sequence[float], seed: int) -> dict[str, Any]:
    """The verdict's figures of one ratio over the worlds (``studies.suites.statistics``):
    the geometric mean with its 95 % BCa bootstrap interval and the win rate with its Wilson
    interval, so that the small suite reports how little it can tell."""
    from studies.suites.statistics import ratio_estimate, wilson

    r = np.asarray(ratios, np.float64)
    r = r[np.isfinite(r) & (r > 0)]
    return {**ratio_estimate(r, seed=seed).to_json(),
            "win_rate": wilson(int((r < 1).sum()), len(r)).to_json(), "worlds": len(r)}


def noise_summary(scores: Sequence[WorldScore], worst_target: float) -> dict[str, Any]:
    """How far runs of one setting are from each other (module docstring), against the
    worst-world target."""
    cv_median = {}
    for setting in ("baseline", "fixed", "adaptive"):
        per_world = [cv(s.runs(setting)) for s in scores]
        ok = [v for v in per_world if math.isfinite(v)]
        cv_median[setting] = float(np.median(ok)) if ok else None
    pairs = pair_ratios(s.runs(setting) for s in scores for setting in ("baseline", "fixed"))
    failed = sum(not math.isfinite(v) for s in scores for runs in s.replicas_rte_pct.values()
                 for v in runs)
    return {"cv_median": cv_median,
            "chance_above_worst_target": float((pairs > worst_target).mean()) if len(pairs)
            else None,
            "chance_ratio_p95": float(np.quantile(pairs, 0.95)) if len(pairs) else None,
            "failed_replicas": failed}


def cv(values: Sequence[float]) -> float:
    """Coefficient of variation (population std / mean) of the finite values; NaN below 2."""
    v = np.asarray([x for x in values if math.isfinite(x)], np.float64)
    return float(v.std() / v.mean()) if len(v) >= 2 and v.mean() > 0 else math.nan


def pair_ratios(groups: Iterable[Sequence[float]]) -> NDArray[np.float64]:
    """a / b over every ordered pair of two distinct finite runs (a, b > 0 RTE [%]) of each
    group (the runs of one setting on one world), all groups pooled: (P,)."""
    return np.array([a / b for runs in groups for i, a in enumerate(runs)
                     for j, b in enumerate(runs)
                     if i != j and b > 0 and math.isfinite(a) and math.isfinite(b)], np.float64)


def generalization_rows(scores: Sequence[WorldScore]) -> list[dict[str, Any]]:
    """One row per world for ``dvc plots``: RTE of every setting and the three ratios (with
    replicas also every setting's median over its runs and the ratios of those)."""
    def num(v: float) -> float | str:
        return round(float(v), 6) if math.isfinite(v) else ""

    return [{"world": s.name, "segments": "-".join(s.segments), "sensor": s.sensor,
             "frames": s.frames, **{f"{k}_pct": num(v) for k, v in s.rte_pct.items()},
             **{k: num(v) for k, v in s.ratios().items()},
             **({f"{k}_median_pct": num(v) for k, v in s.replica_medians().items()}
                if s.replicas_rte_pct else {}),
             **({f"replica_{k}": num(v) for k, v in s.replica_ratios().items()}
                if s.replicas_rte_pct else {})} for s in scores]
