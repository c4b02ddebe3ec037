"""The worlds of the verdict's suites: composites drawn from a frozen seed root.

World i of a family's suite (``id`` or ``ood``; ``dev`` or ``test``) depends on the suite's seed
root and i alone (``numpy.random.default_rng([root, i])``, so more worlds only append):
- 2 to 4 segments (``segments``) drawn from ``labels``, never the same label twice in a row
  (``pipeline.generalization.suite.draw_labels``), in a random order;
- its frames drawn from ``frames`` (900 to 1200), the segments sharing them evenly;
- a simulation seed from the same generator;
- the sensor ``sensors[i % len(sensors)]``.
Every world is simulated with the training data's sensor settings (noise, dropout, motion
distortion and whatever else ``SimSpec`` carries): the spec of the first training sequence of
the ``simulate`` section with the world, seed, frames, sensor and segments replaced, so training
and suites see the same sensor model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.errors import ConfigError
from pipeline.generalization.suite import draw_labels
from pipeline.sim import GENERATOR_VERSION
from pipeline.sim.dataset import SimulateSection, dataset_specs
from pipeline.sim.simulate import SimSpec
from pipeline.verdict.section import SuiteDraw, VerdictSection


@dataclass(frozen=True)
class VerdictWorld:
    """One world of a suite: its name (``<family>_<suite>_<i>``), family and what to simulate."""

    name: str
    family: str
    spec: SimSpec

    @property
    def description(self) -> str:
        """``cave-street-cave, hdl32, 1000 frames``."""
        return f"{'-'.join(self.spec.segments)}, {self.spec.sensor}, {self.spec.frames} frames"


def suite_worlds(section: VerdictSection, family: str, template: SimSpec) -> list[VerdictWorld]:
    """The worlds of ``family``'s chosen suite (``section.suite``), in order; ConfigError when
    the world generator is not the one the suites were frozen with."""
    check_generator(section)
    draw = section.suites.draw(family)
    return [world_of(draw, family, section.suite, i, template) for i in range(draw.worlds)]


def world_of(draw: SuiteDraw, family: str, suite: str, i: int, template: SimSpec) -> VerdictWorld:
    """World ``i`` of ``family``'s ``suite``: from (the suite's seed root, i) alone."""
    rng = np.random.default_rng([draw.seed_roots[suite], i])
    n = int(rng.integers(draw.segments[0], draw.segments[1] + 1))
    labels = draw_labels(rng, n, draw.labels)
    frames = int(rng.integers(draw.frames[0], draw.frames[1] + 1))
    seed = int(rng.integers(2**31 - 1))
    spec = replace(template, world="composite", seed=seed, frames=frames,
                   sensor=draw.sensors[i % len(draw.sensors)], segments=labels)
    return VerdictWorld(f"{family}_{suite}_{i:02d}", family, spec)


def sensor_template(simulate: SimulateSection, base_seed: int) -> SimSpec:
    """The spec of the first training sequence: the sensor settings every suite world gets."""
    return next(spec for split, spec in dataset_specs(simulate, base_seed).values()
                if split == "train")


def check_generator(section: VerdictSection) -> None:
    """ConfigError unless ``pipeline.sim.GENERATOR_VERSION`` is ``verdict.world_generator``."""
    if section.world_generator != GENERATOR_VERSION:
        raise ConfigError(
            f"verdict.world_generator: the suites were frozen with world generator "
            f"{section.world_generator}, this code simulates version {GENERATOR_VERSION}; record "
            f"the new version in the params file in a commit of its own before running it, "
            f"got {section.world_generator}")
