"""Synthetic worlds of a verdict suite (studies/suites/runner.py's WorldResult) for the tests of
its statistics, summary and page."""

from __future__ import annotations

import numpy as np

from studies.suites.runner import WorldResult


def world(name: str, runs: dict[str, list[list[float]]], labels: list[str],
          failed: dict[str, list[bool]] | None = None) -> WorldResult:
    """A world whose setting s has the per-start-frame RTE rows ``runs[s]`` (one per run)."""
    t = {s: np.array(v, np.float64) for s, v in runs.items()}
    return WorldResult(name, "id", ("cave", "street"), "hdl32", len(labels), 7, labels, t,
                       failed or {s: [False] * len(v) for s, v in runs.items()},
                       {"adaptive": {"changes": 3, "novel_share": 0.25, "edge_share": 0.0}},
                       1.0)
