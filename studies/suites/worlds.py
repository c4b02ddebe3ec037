"""The subjects of a suite: simulated worlds drawn from a seed root (``SimulatedWorld``) and
recorded runs (``RecordedRun``), each loadable into memory for the runner.

World i of a suite depends on the suite's seed root and i alone
(``numpy.random.default_rng([root, i])``, so more worlds only append), drawn in this order:
- its number of segments from ``segments`` (min, max);
- that many labels from ``labels``, never the same one twice in a row (``draw_labels``);
- its frames: from ``frames`` (min, max) per world, the segments sharing them, or from
  ``segment_frames`` per segment, the world holding that many times its segments;
- a simulation seed;
- and the sensor ``sensors[i % len(sensors)]``.
It is simulated with the spec ``template`` (the sensor effects and motion of the training data)
with the world, seed, frames, sensor and segments replaced. The toy's generalization suite and
the verdict's suites draw their worlds with ``draw_world`` (``studies.generalization.suite``,
``studies.verdict.worlds``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from pipeline.sequence import Scan
from pipeline.sim.route import LABELS
from pipeline.sim.simulate import SimSpec

SUITES = ("dev", "test")
"""A suite family's two suites: ``dev`` (every choice is made there) and ``test`` (reported)."""


class Subject(Protocol):
    """What a suite runs its settings on: a name, the family and sensor it belongs to, its
    environment segments, frames and seed, what loading it costs (the runner starts the
    costliest first) and its scans with their environment labels."""

    @property
    def name(self) -> str: ...

    @property
    def family(self) -> str: ...

    @property
    def sensor(self) -> str: ...

    @property
    def segments(self) -> tuple[str, ...]: ...

    @property
    def frames(self) -> int: ...

    @property
    def seed(self) -> int: ...

    @property
    def cost(self) -> int: ...

    @property
    def length_m(self) -> float | None:
        """Its own L [m], or None: the suite's."""
        ...

    @property
    def jump_limit_m(self) -> float | None:
        """A frame-to-frame translation above this [m] fails a run, as a trial's
        (``pipeline.tuning.job.check_jump``); None: no such check."""
        ...

    def load(self) -> tuple[list[Scan], list[str]]: ...


@dataclass(frozen=True)
class SimulatedWorld:
    """A world of a suite: its name (``<family>_<suite>_<i>`` or ``<suite>_<i>``), family and
    what to simulate."""

    name: str
    family: str
    spec: SimSpec
    length_m: float | None = None
    jump_limit_m: float | None = None

    @property
    def sensor(self) -> str:
        return self.spec.sensor

    @property
    def segments(self) -> tuple[str, ...]:
        return self.spec.segments

    @property
    def frames(self) -> int:
        return self.spec.frames

    @property
    def seed(self) -> int:
        return self.spec.seed

    @property
    def cost(self) -> int:
        """Rays fired over the world (``SimSpec.rays``)."""
        return self.spec.rays()

    @property
    def description(self) -> str:
        """``cave-street-cave, hdl32, 1000 frames``."""
        return f"{'-'.join(self.segments)}, {self.sensor}, {self.frames} frames"

    def load(self) -> tuple[list[Scan], list[str]]:
        """The world simulated into memory (``pipeline.sim.simulate.simulate_scans``): its
        scans and each frame's environment label."""
        from pipeline.sim.simulate import simulate_scans

        sim = simulate_scans(self.spec)
        return sim.scans, sim.labels


@dataclass(frozen=True)
class RecordedRun:
    """A recorded run (a sequence MCAP with ground truth, e.g. a piece of a real recording):
    its name, family (the fold it is tested in), sensor, frames, its own L [m] (None: the
    suite's) and jump limit [m] (None: none)."""

    name: str
    family: str
    path: Path
    sensor: str
    frames: int
    length_m: float | None = None
    jump_limit_m: float | None = None
    segments: tuple[str, ...] = ()
    seed: int = 0

    @property
    def cost(self) -> int:
        """Its file's size [bytes]."""
        return self.path.stat().st_size

    def load(self) -> tuple[list[Scan], list[str]]:
        """Its scans and each frame's environment label ('' where it has none)."""
        from pipeline.sequence import SequenceReader

        with SequenceReader(self.path) as reader:
            scans = list(reader)
            labels = [reader.info.label_of(i) or "" for i in range(len(scans))]
        return scans, labels


def draw_world(name: str, family: str, root: int, i: int, *, segments: tuple[int, int],
               labels: tuple[str, ...], sensors: tuple[str, ...], template: SimSpec,
               frames: tuple[int, int] | None = None,
               segment_frames: tuple[int, int] | None = None) -> SimulatedWorld:
    """World ``i`` of the suite of seed root ``root`` (module docstring): ``frames`` per world
    or ``segment_frames`` per segment, exactly one of them."""
    rng = np.random.default_rng([root, i])
    n = int(rng.integers(segments[0], segments[1] + 1))
    drawn = draw_labels(rng, n, labels)
    if (frames is None) == (segment_frames is None):
        raise ValueError("give frames per world or segment_frames per segment")
    if frames is not None:
        total = int(rng.integers(frames[0], frames[1] + 1))
    else:
        assert segment_frames is not None
        total = n * int(rng.integers(segment_frames[0], segment_frames[1] + 1))
    seed = int(rng.integers(2**31 - 1))
    spec = replace(template, world="composite", seed=seed, frames=total,
                   sensor=sensors[i % len(sensors)], segments=drawn)
    return SimulatedWorld(name, family, spec)


def draw_labels(rng: np.random.Generator, n: int, labels: tuple[str, ...]) -> tuple[str, ...]:
    """``n`` segment labels drawn from ``labels``, never the same one twice in a row."""
    out = [str(rng.choice(labels))]
    while len(out) < n:
        out.append(str(rng.choice([lab for lab in labels if lab != out[-1]])))
    return tuple(out)


def seed_roots_rule(v: Mapping[str, int]) -> dict[str, int]:
    """``v`` unless it is not one root for each of the suites ``SUITES``, all different."""
    missing = [s for s in SUITES if s not in v]
    if missing or set(v) - set(SUITES):
        raise ValueError(f"needs exactly the suites {', '.join(SUITES)}, got {sorted(v)}")
    if v["dev"] == v["test"]:
        raise ValueError(f"the dev and test roots must differ, got {v['dev']} for both")
    return dict(v)


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
