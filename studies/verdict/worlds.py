"""The worlds of the verdict's suites: composites drawn from a frozen seed root.

World i of a family's suite (``id`` or ``ood``; ``dev`` or ``test``) is drawn by
``studies.suites.worlds.draw_world`` from (the suite's seed root, i) alone: 2 to 4 segments
(``segments``), its frames drawn from ``frames`` (900 to 1200) per world, the segments sharing
them, and the sensor ``sensors[i % len(sensors)]``. Every world is simulated with the training
data's sensor settings (noise, dropout, motion distortion and whatever else ``SimSpec``
carries): the spec of the first training sequence of the ``simulate`` section, so training and
suites see the same sensor model.
"""

from __future__ import annotations

from pipeline.errors import ConfigError
from pipeline.sim import GENERATOR_VERSION
from pipeline.sim.dataset import SimulateSection, dataset_specs
from pipeline.sim.simulate import SimSpec
from studies.suites.worlds import SimulatedWorld, draw_world
from studies.verdict.section import SuiteDraw, VerdictSection


def suite_worlds(section: VerdictSection, family: str, template: SimSpec
                 ) -> list[SimulatedWorld]:
    """The worlds of ``family``'s chosen suite (``section.suite``), in order; ConfigError when
    the world generator is not the one the suites were frozen with."""
    check_generator(section)
    draw = section.suites.draw(family)
    return [world_of(draw, family, section.suite, i, template) for i in range(draw.worlds)]


def world_of(draw: SuiteDraw, family: str, suite: str, i: int, template: SimSpec
             ) -> SimulatedWorld:
    """World ``i`` of ``family``'s ``suite``: from (the suite's seed root, i) alone."""
    return draw_world(f"{family}_{suite}_{i:02d}", family, draw.seed_roots[suite], i,
                      segments=draw.segments, labels=draw.labels, sensors=draw.sensors,
                      frames=draw.frames, template=template)


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
