"""The worlds of a generalization suite: composites the surrogate never trained on.

A suite (``dev``, where selector choices are made, or ``test``, where results are reported) is
a list of composite worlds drawn by ``studies.suites.worlds.draw_world``: 2 to 5 segments
drawn from ``labels`` (repeats such as cave, street, cave occur), the same number of frames for
every segment of a world, drawn from ``segment_frames``, the sensor ``sensors[i %
len(sensors)]`` (the training worlds use the HDL-32E) and a simulation seed, from (the suite's
seed root, i) alone, so a larger ``worlds`` count only appends worlds (the training and toy
validation seeds derive from ``base.seed`` and the sequence name: ``pipeline.sim.dataset``).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.sim.route import LABELS
from pipeline.sim.sensors import SENSORS
from pipeline.sim.simulate import SimSpec
from studies.suites.worlds import (
    SimulatedWorld,
    draw_world,
    labels_rule,
    range_rule,
    seed_roots_rule,
)


class GeneralizeTargets(Section):
    """What the toy's suite is asked, of adaptive / min(baseline, fixed) over its test worlds:
    the median at most, the worst world at most and the win rate at least (docs/results/
    toy.md)."""

    median: float = Field(0.75, gt=0)
    worst: float = Field(1.05, gt=0)
    win_rate: float = Field(0.90, ge=0, le=1)


class GeneralizeSection(Section):
    """params.yaml ``generalize``: which suite, how it is drawn and summarised.

    seed_roots: the root of every suite's seeds (fixed before any result was seen);
    worlds: worlds per suite; segments: (min, max) segments per world; segment_frames: (min,
    max) frames per segment (10 Hz; 0 worlds: no suite, ``studies.generalization.report``);
    bootstrap: resamples of the bootstrap interval of the
    median ratio; replicas: extra runs of every setting on every world with the parameters
    moved by at most ``replica_scale`` (relative), to measure how far one run is from the next
    (``pipeline.evaluate.replicas``; 0: none); workers: worlds run in parallel;
    length_m: the RTE length L (from base); targets: what the suite is asked
    (``GeneralizeTargets``).
    """

    suite: Literal["dev", "test"] = "test"
    seed_roots: dict[str, int] = Field(default_factory=lambda: {"dev": 61403, "test": 90217})
    worlds: int = Field(6, ge=0)
    segments: tuple[int, int] = (2, 5)
    segment_frames: tuple[int, int] = (150, 300)
    labels: tuple[str, ...] = LABELS
    sensors: tuple[str, ...] = ("hdl32", "vlp16", "hdl32", "hdl64")
    bootstrap: int = Field(2000, ge=100)
    replicas: int = Field(2, ge=0)
    replica_scale: float = Field(0.005, gt=0, le=0.1)
    workers: int = Field(2, ge=1)
    length_m: float = Field(25.0, gt=0)
    targets: GeneralizeTargets = Field(
        default_factory=lambda: GeneralizeTargets.model_validate({}))

    @field_validator("seed_roots")
    @classmethod
    def _roots(cls, v: dict[str, int]) -> dict[str, int]:
        return seed_roots_rule(v)

    @field_validator("segments", "segment_frames")
    @classmethod
    def _range(cls, v: tuple[int, int]) -> tuple[int, int]:
        return range_rule(v)

    @field_validator("labels")
    @classmethod
    def _labels(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        return labels_rule(v)

    @field_validator("sensors")
    @classmethod
    def _sensors(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        bad = [s for s in v if s not in SENSORS]
        if bad or not v:
            raise ValueError(f"must be a non-empty list of {', '.join(SENSORS)}, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _frames(self) -> GeneralizeSection:
        if self.segments[0] * self.segment_frames[0] < 30:
            raise ValueError(f"a world needs >= 30 frames, got segments={list(self.segments)} "
                             f"of segment_frames={list(self.segment_frames)}")
        return self

    @property
    def root(self) -> int:
        """The seed root of the chosen suite."""
        return self.seed_roots[self.suite]


def generalization_worlds(section: GeneralizeSection) -> list[SimulatedWorld]:
    """The worlds of ``section.suite`` (module docstring), in order."""
    return [generalization_world(section, section.suite, i) for i in range(section.worlds)]


def generalization_world(section: GeneralizeSection, suite: str, i: int) -> SimulatedWorld:
    """World ``i`` of ``suite``: from (the suite's seed root, i) alone (``draw_world``, with the
    toy worlds' sensor model: ``SimSpec``'s defaults)."""
    return draw_world(f"{suite}_{i:02d}", "", section.seed_roots[suite], i,
                      segments=section.segments, labels=section.labels,
                      sensors=section.sensors, segment_frames=section.segment_frames,
                      template=SimSpec("composite", 0, 1))
