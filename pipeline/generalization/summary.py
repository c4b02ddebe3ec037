"""The suite's figures: per-world ratios and their median, worst world, win rate and a
bootstrap interval of the median (``metrics/generalization.json``, ``plots/generalization.csv``).

A ratio below 1 means adaptive beat the other setting on that world (lower RTE); the win rate
is the fraction of worlds whose ratio is below 1. The interval is the percentile bootstrap
(worlds resampled with replacement, ``resamples`` times, seeded) of the median ratio.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pipeline.generalization.run import WorldScore

RATIOS = ("adaptive_vs_best", "adaptive_vs_baseline", "adaptive_vs_fixed")
INTERVAL = 0.90


def ratio_summary(names: Sequence[str], ratios: Sequence[float], resamples: int,
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


def suite_metrics(scores: Sequence[WorldScore], suite: str, root: int, resamples: int,
                  algorithm: str, length_m: float) -> dict[str, Any]:
    """The JSON of ``metrics/generalization.json``: the suite, every world, every ratio's
    summary (module docstring)."""
    names = [s.name for s in scores]
    summary = {k: ratio_summary(names, [s.ratios()[k] for s in scores], resamples, root)
               for k in RATIOS}
    return {
        "algorithm": algorithm,
        "suite": suite,
        "seed_root": root,
        "length_m": length_m,
        "worlds": len(scores),
        "frames": sum(s.frames for s in scores),
        "summary": summary,
        "per_world": {s.name: s.to_json() for s in scores},
    }


def plot_rows(scores: Sequence[WorldScore]) -> list[dict[str, Any]]:
    """One row per world for ``dvc plots``: RTE of every setting and the three ratios."""
    def num(v: float) -> float | str:
        return round(float(v), 6) if math.isfinite(v) else ""

    return [{"world": s.name, "segments": "-".join(s.segments), "sensor": s.sensor,
             "frames": s.frames, **{f"{k}_pct": num(v) for k, v in s.rte_pct.items()},
             **{k: num(v) for k, v in s.ratios().items()}} for s in scores]
