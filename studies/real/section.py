"""params ``real`` (``RealSection``): the real-data study's runs, folds' settings and statistics
(docs/results/real.md; real/params.yaml holds them, frozen before any test fold ran).

The runs themselves are sources of the params ``data`` section (ingested by the product's own
ingest stage, each with its split limits and its own RTE length); this section says what each
run is to the study: its sensor (the deploy models are one per sensor and algorithm) and
whether it takes part in the out-of-environment folds (a hand-held solid-state run: leave one
out; riverside02 has no second drive). Per algorithm: the search space the studies search and
the adapter's untuned options. The statistics: replicas, the moving-block bootstrap, the
failure threshold per RTE length, the fold plotted in the docs.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.tuning.section import SpaceRange


class RealRun(Section):
    """One run of the study: the ``data`` source of that name, its sensor, whether it is left
    out in turn by the out-of-environment folds, and the reference system's own odometry
    (``odometry``: a KITTI pose file, a pose per line of the source's times file; relative to
    the params file), which the report scores as the reference's floor."""

    name: str
    sensor: str
    out_of_environment: bool = True
    odometry: str = Field(min_length=1)


class RealSection(Section):
    """params.yaml ``real`` (module docstring).

    algorithms: the odometry algorithms studied, each fold and statistic per algorithm;
    runs: the runs (``RealRun``); spaces / adapter_options: per algorithm, the search ranges
    (as ``trials.space``) and untuned options (as ``trials.adapter_options``); candidates_k:
    the surrogate's k values a fold's cross-validation over its own training units chooses
    from (the default k where a fold has a single training unit); replicas / replica_scale:
    extra runs of every setting, parameters moved by at most that much (>= 3 replicas);
    resamples / confidence: the moving-block bootstrap of a run's ratios; failure_pct: per RTE
    length L [m], a sub-trajectory with a larger RTE [%] fails (the pooled failure rate);
    plot_fold: the fold whose trajectories the docs draw; workers: units run at a time;
    targets: what the study is asked (``studies.real.summary.targets``).
    """

    algorithms: tuple[str, ...] = ("gicp", "ndt", "kiss_icp")
    runs: list[RealRun] = Field(default_factory=list)
    spaces: dict[str, dict[str, SpaceRange]] = Field(default_factory=dict)
    adapter_options: dict[str, dict[str, Any]] = Field(default_factory=dict)
    candidates_k: tuple[int, ...] = (5, 20, 100)
    replicas: int = Field(3, ge=3)
    replica_scale: float = Field(0.005, gt=0, le=0.1)
    resamples: int = Field(10000, ge=100)
    confidence: float = Field(0.95, gt=0, lt=1)
    failure_pct: dict[float, float] = Field(default_factory=dict)
    plot_fold: str = "in_a"
    workers: int = Field(2, ge=1)
    targets: dict[str, float] = Field(default_factory=lambda: {
        "fixed_vs_baseline": 0.50, "adaptive_vs_fixed_in": 0.85, "adaptive_vs_fixed_out": 1.00,
        "worst_run": 1.10})

    @field_validator("candidates_k")
    @classmethod
    def _k(cls, v: tuple[int, ...]) -> tuple[int, ...]:
        if not v or min(v) < 1:
            raise ValueError(f"must be at least one k >= 1, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _runs(self) -> RealSection:
        names = [r.name for r in self.runs]
        if len(set(names)) < len(names):
            raise ValueError(f"runs: every run once, got {names}")
        foreign = sorted(set(self.spaces) - set(self.algorithms))
        if foreign:
            raise ValueError(f"spaces: {foreign} are no algorithm of the study "
                             f"({', '.join(self.algorithms)})")
        return self

    def failure_threshold(self, length_m: float) -> float:
        """The failure threshold [%] of sub-trajectories of ``length_m`` (ValueError for a
        length without one)."""
        for length, pct in self.failure_pct.items():
            if abs(float(length) - length_m) < 1e-9:
                return float(pct)
        raise ValueError(f"real.failure_pct: no threshold for L = {length_m:g} m (known: "
                         f"{', '.join(f'{k:g}' for k in self.failure_pct)})")

    def run(self, name: str) -> RealRun:
        """The run called ``name`` (ValueError naming the known ones)."""
        for r in self.runs:
            if r.name == name:
                return r
        raise ValueError(f"real.runs: no run {name!r} (known: "
                         f"{', '.join(r.name for r in self.runs)})")
