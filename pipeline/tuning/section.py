"""The tuning's params sections: ``trials`` (the per-sequence studies, ``TrialsSection``) and
``fixed`` (what the joint study does differently, ``FixedSection``), and the one place the
second overrides the first (``joint_settings``). The stages that only read a setting import
this module, not the SMBO engine (``pipeline.tuning.smbo``)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from pipeline.config import IterationCount, Section, validate_section
from pipeline.errors import ConfigError
from pipeline.tuning.pruning import Fidelity, HalvingSection, PruningSection, StoppingRule

FailureRule = Literal["trial", "sequence"]
"""How a trial over several sequences (the joint study's) counts one whose odometry fails:
``trial`` (the whole trial fails, at the penalty) or ``sequence`` (that sequence alone counts
at the penalty in the mean over the sequences; ``pipeline.tuning.job``)."""


class SpaceRange(Section):
    """One parameter's search range in ``trials.space``; unset fields keep the adapter's."""

    low: float | None = Field(None, strict=True, allow_inf_nan=False)
    high: float | None = Field(None, strict=True, allow_inf_nan=False)
    default: float | None = Field(None, strict=True, allow_inf_nan=False)
    log: bool | None = Field(None, strict=True)


class TrialsSection(Section):
    """params.yaml ``trials``: settings of the SMBO trials (also used by the joint ``fixed`` stage).

    penalty_pct: objective [%] of a failed trial (fixed, not relative to the baseline, so that
    history and resume are deterministic; well above any sane mean RTE).
    time_limit_s: per sequence run (a joint trial gets the sum); null = no limit, in-process.
    jump_limit_m: a frame-to-frame translation above this fails the trial (diverged odometry).
    startup_trials: random proposals before TPE (hyperopt's n_startup_jobs).
    retries: times a lost trial (process killed from outside, executor broken) is run again
    before the run gives up on it (a resume runs it again).
    fidelity: ``whole`` (every trial runs every frame of its sequences, the paper's protocol;
    ``pruning`` may stop hopeless ones) or ``halving`` (successive halving over the rungs of
    ``halving``: a trial runs on to the next fraction of its sequences only when it is among
    the best 1/eta there; ``pipeline.tuning.pruning``). docs/design.md, "Stages".
    pruning: with ``fidelity: whole``, stop hopeless trials early (``percentile: null`` turns it
    off).
    space: search ranges that replace the adapter's built-in ones, by parameter name
    (``{resolution: {low: 0.5, high: 8}}``; ``adaptune params ALGO`` lists them). The space a
    study used is stored with its trials table, where the later stages read it.
    dask: null = process pool; "local" = a Dask LocalCluster of ``workers`` processes;
    "tcp://host:port" = an existing Dask scheduler.
    failures: how a trial over several sequences counts one whose odometry fails
    (``FailureRule``); the joint study's is ``fixed.failures`` (``joint_settings``). A study of
    one sequence fails the trial under either rule.
    """

    algorithm: str = "ndt"
    iterations: IterationCount = 256
    workers: int = Field(2, ge=1)
    dask: str | None = None
    time_limit_s: float | None = Field(600.0, gt=0)
    penalty_pct: float = Field(100.0, gt=0)
    length_m: float = Field(25.0, gt=0)
    jump_limit_m: float = Field(5.0, gt=0)
    startup_trials: int = Field(20, ge=1)
    retries: int = Field(2, ge=0)
    split: str = "train"
    adapter_options: dict[str, Any] = Field(default_factory=dict)
    space: dict[str, SpaceRange] = Field(default_factory=dict)
    fidelity: Fidelity = "whole"
    halving: HalvingSection = Field(default_factory=lambda: HalvingSection.model_validate({}))
    pruning: PruningSection = Field(default_factory=lambda: PruningSection.model_validate({}))
    failures: FailureRule = "trial"

    @property
    def stopping(self) -> StoppingRule:
        """How the study stops trials (``pipeline.tuning.pruning.StoppingRule``)."""
        return StoppingRule.of(self.fidelity, self.pruning, self.halving)

    @model_validator(mode="after")
    def _options_of_the_algorithm(self) -> TrialsSection:
        """adapter_options another algorithm takes (left by a change of ``algorithm``) are one
        line naming them and how to drop them, at the load of params.yaml by any stage."""
        if not self.adapter_options or ":" in self.algorithm:  # a factory: its own checks
            return self
        from pipeline.odometry.registry import option_names

        known = option_names(self.algorithm)  # ConfigError for an unknown algorithm
        foreign = sorted(set(self.adapter_options) - set(known))
        if foreign:
            raise ConfigError(
                f"trials.adapter_options: {', '.join(foreign)} are not options of "
                f"{self.algorithm} (its options: {', '.join(known)}): left by another "
                f"algorithm? drop them with `dvc exp run -S trials.algorithm={self.algorithm} "
                "-S '~trials.adapter_options'`, or delete them from params.yaml")
        return self

    @field_validator("dask")
    @classmethod
    def _dask_address(cls, v: str | None) -> str | None:
        if v is None or v == "local":
            return v
        from urllib.parse import urlsplit

        parts = urlsplit(v)
        try:
            port = parts.port
        except ValueError:  # not a number, or out of range
            port = None
        if not parts.scheme or not parts.hostname or port is None or port < 1 or (
                parts.path not in ("", "/")):
            raise ValueError("dask must be 'local' or a scheduler address scheme://host:port "
                             f"(a port in 1-65535), like tcp://host:8786, got {v!r}")
        return v


class FixedSection(Section):
    """params.yaml ``fixed``: what the joint study (the paper's "fixed" parameters) does
    differently from ``trials``; null keeps the ``trials`` value. The defaults are params.yaml's
    (64 iterations after a warm start of 4, its own pruner at the 50th percentile).

    warm_start: the joint study starts from what the per-sequence studies measured: after the
    baseline, its first ``warm_start`` trials are the parameter sets they predict best for all
    sequences together (``pipeline.tuning.warm_start``), not random ones; 0 = off.
    pruning: the joint study's own pruner settings (null = ``trials.pruning``): its trials run
    every training sequence, and its rows do not train the surrogate.
    fidelity, halving: the joint study's own (null = ``trials.fidelity`` / ``trials.halving``).
    failures: what a sequence whose odometry fails does to a joint trial (``FailureRule``):
    ``trial`` (the default: the trial fails, at the penalty) or ``sequence`` (the trial is ok
    when any sequence finished, its objective the mean over all of them with each failed one
    at the penalty; docs/design.md, "Stages").
    """

    iterations: IterationCount | None = 64
    workers: int | None = Field(None, ge=1)
    warm_start: int = Field(4, ge=0)
    pruning: PruningSection | None = Field(
        default_factory=lambda: PruningSection.model_validate({"percentile": 50.0}))
    fidelity: Fidelity | None = None
    halving: HalvingSection | None = None
    failures: FailureRule = "trial"


def joint_settings(trials: TrialsSection, fixed: FixedSection) -> TrialsSection:
    """The joint study's settings: ``trials`` with every value ``fixed`` sets (the
    ``fixed`` stage, the verdict's frozen budget check, the bench's offline toy)."""
    return validate_section(TrialsSection, "trials", {
        **trials.model_dump(), **fixed.model_dump(exclude_none=True, exclude={"warm_start"})})
