"""A world's score as the toy's generalization suite reports it (``WorldScore``), from its runs
by the suite runner (``studies.suites.runner``: baseline, fixed and adaptive, the nominal run and
``replicas`` more, per-start-frame RTE at L; a failed run has no score here, as a failed replica
of the evaluate stage)."""

from __future__ import annotations

import math
import statistics
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from pipeline.evaluate.result import SETTINGS, finite_mean
from studies.suites.runner import WorldResult


@dataclass(frozen=True)
class WorldScore:
    """One world's result: mean per-start-frame RTE [%] of every setting, overall and per
    environment label, the adaptive run's parameter changes and the wall time [s]; with
    replicas (``pipeline.evaluate.replicas``) the RTE [%] of every replica run of every
    setting (NaN: the odometry failed)."""

    name: str
    segments: tuple[str, ...]
    sensor: str
    frames: int
    seed: int
    rte_pct: dict[str, float]
    rte_pct_per_label: dict[str, dict[str, float]]
    parameter_changes: int
    wall_time_s: float
    replicas_rte_pct: dict[str, list[float]] = field(default_factory=dict)

    @property
    def best_fixed_setting(self) -> str:
        """The better of baseline and fixed on this world."""
        return min(("baseline", "fixed"), key=lambda s: self.rte_pct[s])

    def ratios(self) -> dict[str, float]:
        """adaptive / baseline, adaptive / fixed and adaptive / min(baseline, fixed)."""
        return _ratios(self.rte_pct)

    def runs(self, setting: str) -> list[float]:
        """RTE [%] of the nominal run and of every replica of ``setting``."""
        return [self.rte_pct[setting], *self.replicas_rte_pct.get(setting, [])]

    def replica_medians(self) -> dict[str, float]:
        """Per setting, the median RTE [%] over its nominal and replica runs (failed left out)."""
        return {s: _nanmedian(self.runs(s)) for s in self.rte_pct}

    def replica_ratios(self) -> dict[str, float]:
        """The three ratios of the settings' medians over their runs: what one run says with
        the parameters' chaos averaged out."""
        return _ratios(self.replica_medians())

    def to_json(self) -> dict[str, Any]:
        out = {**asdict(self), "segments": list(self.segments), "ratio": self.ratios()}
        if self.replicas_rte_pct:
            out["replica_ratio"] = self.replica_ratios()
        return out


def _ratios(rte_pct: dict[str, float]) -> dict[str, float]:
    a, b, f = (rte_pct[s] for s in ("adaptive", "baseline", "fixed"))
    return {"adaptive_vs_baseline": _ratio(a, b), "adaptive_vs_fixed": _ratio(a, f),
            "adaptive_vs_best": _ratio(a, min(b, f))}


def _nanmedian(values: list[float]) -> float:
    ok = [v for v in values if math.isfinite(v)]
    return float(statistics.median(ok)) if ok else math.nan


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 and math.isfinite(a) and math.isfinite(b) else math.nan


def world_score(result: WorldResult, adaptive: str = "adaptive") -> WorldScore:
    """The toy's view of one world's runs (``studies.suites.runner``): the nominal run's RTE
    of every setting, overall and per label, the replicas' RTE (NaN: failed) and the adaptive
    schedule's parameter changes; every mean the evaluate stage's (``finite_mean``), as the
    toy's figures have always been."""
    labels = np.array(result.labels)
    names = [lab for lab in dict.fromkeys(result.labels) if lab]
    t = {s: result.t_err_pct[s] for s in ("baseline", "fixed", adaptive)}
    return WorldScore(
        result.name, result.segments, result.sensor, result.frames, result.seed,
        {s: finite_mean(t[s][0]) for s in SETTINGS},
        {s: {lab: finite_mean(t[s][0][labels == lab]) for lab in names} for s in SETTINGS},
        int(result.selection[adaptive]["changes"]), result.wall_time_s,
        {s: [finite_mean(row) for row in t[s][1:]] for s in SETTINGS} if len(t["fixed"]) > 1
        else {})
