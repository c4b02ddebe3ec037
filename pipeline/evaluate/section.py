"""params.yaml ``evaluate``: which splits the ``adaptive`` and ``evaluate`` stages run, the RTE
length, the devkit lengths, the workers and the replicas (``pipeline.evaluate.replicas``)."""

from __future__ import annotations

from pydantic import Field, field_validator

from pipeline.config import Section
from pipeline.metrics.section import DevkitSection


class EvaluateSection(Section):
    """params.yaml ``evaluate`` (also read by the ``adaptive`` stage for its splits).

    splits: the splits of index.json to evaluate on, the headline one first (e.g.
    [validation, train] for the KITTI protocol's test and training sequences); length_m: RTE
    segment length [m] (the trials' L); devkit: the devkit metric's lengths to try (those longer
    than a sequence are left out, as the devkit does); workers: sequences run at a time by the
    ``adaptive`` and ``evaluate`` stages (processes; the same results for any number);
    replicas: extra runs of every setting with the parameters moved by at most
    ``replica_scale`` (relative; ``pipeline.evaluate.replicas``; 0: none).
    """

    splits: list[str] = Field(default_factory=lambda: ["validation"], min_length=1)
    length_m: float = Field(25.0, gt=0)
    devkit: DevkitSection = DevkitSection.model_validate({})
    workers: int = Field(default=2, ge=1)
    replicas: int = Field(default=0, ge=0)
    replica_scale: float = Field(default=0.005, gt=0, le=0.1)

    @field_validator("splits")
    @classmethod
    def _distinct(cls, v: list[str]) -> list[str]:
        twice = sorted({s for s in v if v.count(s) > 1})
        if twice:
            raise ValueError(f"splits must be distinct, {twice[0]!r} is listed twice")
        return v
