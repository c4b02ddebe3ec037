"""A suite's figures (``metrics/<family>.json``), from its worlds' runs
(``studies.suites.runner``) and the statistics of ``studies.suites.statistics``.

Per world, every setting's RTE is the median over its runs; the ratios of two settings are the
ratios of those medians (``adaptive_vs_best``: adaptive / min(baseline, fixed)). Per ratio over
the worlds: the geometric mean and its 95 % bootstrap interval, the win rate (ratio < 1) and its
Wilson interval, the spread of the log ratios and the smallest effect the suite detects (the
power analysis). Per setting: the pooled RTE and failure rate over every sub-trajectory of
every run, overall and per environment label; what the selector did (parameter changes,
unfamiliar scans, frames at the range's edge), and the runs that failed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from studies.suites.runner import FIXED_SETTINGS, WorldResult, world_failures
from studies.suites.statistics import (
    detectable_ratio,
    log_spread,
    pooled,
    ratio_estimate,
    wilson,
)

RATIOS = {"adaptive_vs_fixed": ("fixed",), "adaptive_vs_baseline": ("baseline",),
          "adaptive_vs_best": ("min",)}
"""The suite's ratios of an adaptive setting: name -> the denominator (``WorldResult.ratio``)."""


def suite_metrics(results: Sequence[WorldResult], header: Mapping[str, Any],
                  failure_pct: float, confidence: float, resamples: int, seed: int,
                  adaptive: str = "adaptive",
                  targets: Mapping[str, Mapping[str, tuple[float, float]]] | None = None
                  ) -> dict[str, Any]:
    """The JSON of one suite: ``header`` (what produced it), the ratios of ``adaptive`` and
    their ``targets`` (params ``verdict.targets``), pooled figures, the selector, the failures
    and every world."""
    family = str(header.get("family", ""))
    ratios = {name: ratio_summary([r.ratio(adaptive, den) for r in results], confidence,
                                  resamples, seed)
              for name, (den,) in RATIOS.items()}
    ratios["fixed_vs_baseline"] = ratio_summary([r.ratio("fixed", "baseline") for r in results],
                                                confidence, resamples, seed)
    settings = [*FIXED_SETTINGS, adaptive]
    labels = sorted({lab for r in results for lab in r.labels if lab})
    return {
        **header,
        "worlds": len(results),
        "frames": sum(r.frames for r in results),
        "failure_pct": failure_pct,
        "confidence": confidence,
        "ratios": ratios,
        "targets": targets_met(family, ratios, targets or {}),
        "pooled": {s: pooled([r.t_err_pct[s] for r in results], failure_pct) for s in settings},
        "pooled_per_label": {s: {lab: pooled([r.t_err_pct[s][:, np.array(r.labels) == lab]
                                              for r in results], failure_pct)
                                 for lab in labels} for s in settings},
        "selector": {k: _mean([r.selection[adaptive][k] for r in results])
                     for k in ("changes", "novel_share", "edge_share")},
        "failed_runs": dict(world_failures(results)),
        "per_world": {r.name: world_json(r, settings, adaptive) for r in results},
    }


def ratio_summary(ratios: Sequence[float], confidence: float, resamples: int,
                  seed: int) -> dict[str, Any]:
    """Geometric mean and interval, win rate and Wilson interval, log spread and the smallest
    detectable effect of one ratio over the worlds (NaN ratios left out)."""
    r = np.asarray(ratios, np.float64)
    r = r[np.isfinite(r) & (r > 0)]
    est = ratio_estimate(r, confidence, resamples, seed)
    wins = int((r < 1.0).sum())
    spread = log_spread(r)
    return {"geomean": est.value, "low": est.low, "high": est.high,
            "win_rate": wilson(wins, len(r), confidence).to_json(), "wins": wins,
            "worlds": len(r), "worst": float(r.max()) if len(r) else None,
            "log_spread": spread,
            "detectable_ratio": detectable_ratio(spread, len(r), confidence)}


def targets_met(family: str, ratios: Mapping[str, Mapping[str, Any]],
                targets: Mapping[str, Mapping[str, tuple[float, float]]]) -> dict[str, Any]:
    """Per ratio with a target of ``family`` in ``targets``: the target and whether the suite
    meets it."""
    out = {}
    for name, (most, upper) in targets.get(family, {}).items():
        g, high = ratios[name]["geomean"], ratios[name]["high"]
        strict = family == "id"  # id: upper end < 0.90; ood: upper end <= 1.05
        met = (g is not None and high is not None and g <= most
               and (high < upper if strict else high <= upper))
        out[name] = {"geomean_at_most": most, "upper_end": ("<" if strict else "<=", upper),
                     "met": bool(met)}
    return out


def world_json(r: WorldResult, settings: Sequence[str], adaptive: str) -> dict[str, Any]:
    """One world's entry: what it is, every setting's median and runs, the ratios."""
    return {"segments": list(r.segments), "sensor": r.sensor, "frames": r.frames,
            "seed": r.seed,
            "median_rte_pct": {s: r.median(s) for s in settings},
            "runs_rte_pct": {s: r.run_rte(s).tolist() for s in settings},
            "ratios": {name: r.ratio(adaptive, den) for name, (den,) in RATIOS.items()},
            "selection": r.selection.get(adaptive, {})}


def plot_rows(results: Sequence[WorldResult], adaptive: str = "adaptive") -> list[dict[str, Any]]:
    """One row per world for ``dvc plots``: every setting's median RTE and the ratios."""
    def num(v: float) -> float | str:
        return round(float(v), 6) if np.isfinite(v) else ""

    return [{"world": r.name, "segments": "-".join(r.segments), "sensor": r.sensor,
             "frames": r.frames,
             **{f"{s}_pct": num(r.median(s)) for s in (*FIXED_SETTINGS, adaptive)},
             **{name: num(r.ratio(adaptive, den)) for name, (den,) in RATIOS.items()}}
            for r in results]


def _mean(values: Sequence[float]) -> float | None:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else None
