"""Synthetic worlds of a verdict suite (studies/suites/runner.py's WorldResult) for the tests of
its statistics, summary and page; a suite's metrics from per-world medians for the tests of
two arms of one suite (studies.verdict.arms, experiments/verdict_arms.py)."""

from __future__ import annotations

from typing import Any

import numpy as np

from studies.suites.runner import WorldResult


def world(name: str, runs: dict[str, list[list[float]]], labels: list[str],
          failed: dict[str, list[bool]] | None = None, sensor: str = "hdl32") -> WorldResult:
    """A world whose setting s has the per-start-frame RTE rows ``runs[s]`` (one per run)."""
    t = {s: np.array(v, np.float64) for s, v in runs.items()}
    return WorldResult(name, "id", ("cave", "street"), sensor, len(labels), 7, labels, t,
                       failed or {s: [False] * len(v) for s, v in runs.items()},
                       {"adaptive": {"changes": 3, "novel_share": 0.25, "edge_share": 0.0}},
                       1.0)


def suite_metrics(medians: dict[str, dict[str, float]], suite: str = "dev") -> dict[str, Any]:
    """A suite's metrics as studies.verdict.summary writes them, from per-world medians
    ({world: {setting: median RTE [%]}})."""
    from studies.verdict.summary import RATIOS, ratio_summary

    def ratio(w: dict[str, float], den: str) -> float:
        d = min(w["baseline"], w["fixed"]) if den == "min" else w[den]
        return w["adaptive"] / d

    per_world = {name: {"median_rte_pct": m,
                        "ratios": {r: ratio(m, den) for r, (den,) in RATIOS.items()}}
                 for name, m in medians.items()}
    ratios = {r: ratio_summary([w["ratios"][r] for w in per_world.values()], 0.95, 999, 0)
              for r in RATIOS}
    return {"family": "id", "suite": suite, "seed_root": 70101, "per_world": per_world,
            "ratios": ratios}


def world_medians(adaptive_scale: np.ndarray) -> dict[str, dict[str, float]]:
    """Per-world medians of one world per entry of ``adaptive_scale``: baseline and fixed drawn
    in 2-6 %, adaptive 0.6 x fixed x the world's scale x a draw in 0.8-1.2 (seeded)."""
    rng = np.random.default_rng(3)
    out = {}
    for i, scale in enumerate(adaptive_scale):
        b, f = rng.uniform(2.0, 6.0, 2)
        out[f"w{i:02d}"] = {"baseline": float(b), "fixed": float(f),
                            "adaptive": float(0.6 * f * scale * rng.uniform(0.8, 1.2))}
    return out
