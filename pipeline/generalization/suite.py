"""The worlds of a generalization suite: composites the surrogate never trained on.

A suite (``dev``, where selector choices are made, or ``test``, where results are reported) is
a list of composite worlds. World i of a suite depends on the suite's seed root and i alone
(``numpy.random.default_rng([root, i])``), so a larger ``worlds`` count only appends worlds:
- 2 to 5 segments drawn from ``labels``, never the same label twice in a row (so repeats such
  as cave, street, cave occur), in a random order;
- the same number of frames for every segment of a world, drawn from ``segment_frames``;
- the sensor ``sensors[i % len(sensors)]`` (the training worlds use the HDL-32E);
- a simulation seed drawn from the same generator (the training and toy validation seeds
  derive from ``base.seed`` and the sequence name: ``pipeline.sim.dataset``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.sim.route import LABELS
from pipeline.sim.sensors import SENSORS
from pipeline.sim.simulate import SimSpec

SUITES = ("dev", "test")


class GeneralizeSection(Section):
    """params.yaml ``generalize``: which suite, how it is drawn and summarised.

    seed_roots: the root of every suite's seeds (fixed before any result was seen);
    worlds: worlds per suite; segments: (min, max) segments per world; segment_frames: (min,
    max) frames per segment (10 Hz; 0 worlds: no suite, ``pipeline.generalization.report``);
    bootstrap: resamples of the bootstrap interval of the
    median ratio; replicas: extra runs of every setting on every world with the parameters
    moved by at most ``replica_scale`` (relative), to measure how far one run is from the next
    (``pipeline.evaluate.replicas``; 0: none); workers: worlds run in parallel;
    length_m: the RTE length L (from base).
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


def seed_roots_rule(v: dict[str, int]) -> dict[str, int]:
    """``v`` unless it is not one root for each of the suites ``SUITES``, all different."""
    missing = [s for s in SUITES if s not in v]
    if missing or set(v) - set(SUITES):
        raise ValueError(f"needs exactly the suites {', '.join(SUITES)}, got {sorted(v)}")
    if v["dev"] == v["test"]:
        raise ValueError(f"the dev and test roots must differ, got {v['dev']} for both")
    return v


def range_rule(v: tuple[int, int]) -> tuple[int, int]:
    """``v`` unless it is not a (min, max) range with 1 <= min <= max."""
    if not 1 <= v[0] <= v[1]:
        raise ValueError(f"must be (min, max) with 1 <= min <= max, got {list(v)}")
    return v


def labels_rule(v: tuple[str, ...]) -> tuple[str, ...]:
    """``v`` unless it is not at least two distinct environment labels."""
    bad = [s for s in v if s not in LABELS]
    if bad or len(set(v)) < 2:
        raise ValueError(f"must be at least two distinct labels of {', '.join(LABELS)}, "
                         f"got {list(v)}")
    return v


@dataclass(frozen=True)
class SuiteWorld:
    """One world of a suite: its name (``<suite>_<i>``) and what to simulate."""

    name: str
    spec: SimSpec

    @property
    def description(self) -> str:
        """``cave-street-cave, hdl32, 600 frames``."""
        return f"{'-'.join(self.spec.segments)}, {self.spec.sensor}, {self.spec.frames} frames"


def suite_worlds(section: GeneralizeSection) -> list[SuiteWorld]:
    """The worlds of ``section.suite`` (module docstring), in order."""
    return [world_of(section, section.suite, i) for i in range(section.worlds)]


def world_of(section: GeneralizeSection, suite: str, i: int) -> SuiteWorld:
    """World ``i`` of ``suite``: from (the suite's seed root, i) alone."""
    rng = np.random.default_rng([section.seed_roots[suite], i])
    n = int(rng.integers(section.segments[0], section.segments[1] + 1))
    labels = draw_labels(rng, n, section.labels)
    frames = n * int(rng.integers(section.segment_frames[0], section.segment_frames[1] + 1))
    seed = int(rng.integers(2**31 - 1))
    sensor = section.sensors[i % len(section.sensors)]
    return SuiteWorld(f"{suite}_{i:02d}", SimSpec("composite", seed, frames, sensor,
                                                  labels))


def draw_labels(rng: np.random.Generator, n: int, labels: tuple[str, ...]) -> tuple[str, ...]:
    """``n`` segment labels drawn from ``labels``, never the same one twice in a row (the
    composite worlds of every suite: this one and ``pipeline.verdict.worlds``)."""
    out = [str(rng.choice(labels))]
    while len(out) < n:
        out.append(str(rng.choice([lab for lab in labels if lab != out[-1]])))
    return tuple(out)
