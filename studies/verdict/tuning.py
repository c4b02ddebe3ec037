"""The coverage model's tuning suite (docs/results/verdict-protocol.md, "The tuning suite").

The portfolio (``pipeline.portfolio``) learns which member suits which scan from worlds of the
kind the suites hold: long worlds of 2 to 4 environment segments, drawn exactly as the
in-distribution suites draw theirs (``verdict.suites.id``) from a seed root of their own
(``verdict.tuning``), so no suite world is ever trained on. World i is ``id_tune_<i>``; it
depends on (the tuning root, i) alone, so more worlds only append.

``simulate_tuning_suite`` writes them as a sequences folder: ``<name>.mcap`` per world and an
index whose ``train`` split lists every world and whose split per sensor (``hdl32``, ``hdl64``)
lists that sensor's: the portfolio and its surrogate run once per sensor (``adaptune portfolio
--split SENSOR``), since a deployment knows its sensor.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.sequence import Compression
from pipeline.sim.simulate import SimSpec
from studies.suites.worlds import SimulatedWorld
from studies.verdict.section import VerdictSection
from studies.verdict.worlds import check_generator, world_of

TUNING = "tune"
"""The suite name of the tuning worlds (``id_tune_<i>``)."""


def tuning_worlds(section: VerdictSection, template: SimSpec) -> list[SimulatedWorld]:
    """The tuning suite's worlds, in order; ConfigError when the world generator is not the one
    the suites were frozen with."""
    check_generator(section)
    draw = section.suites.id.model_copy(update={
        "seed_roots": {TUNING: section.tuning.seed_root}, "worlds": section.tuning.worlds})
    return [world_of(draw, "id", TUNING, i, template) for i in range(draw.worlds)]


def tuning_index(worlds: list[SimulatedWorld]) -> dict[str, list[str]]:
    """The sequences index of the tuning folder: ``train`` every world, then one split per
    sensor (in the order the sensors first appear) with its worlds."""
    index: dict[str, list[str]] = {"train": [w.name for w in worlds], "validation": []}
    for w in worlds:
        index.setdefault(w.spec.sensor, []).append(w.name)
    return index


def simulate_tuning_suite(worlds: list[SimulatedWorld], out_dir: str | Path, workers: int,
                          compression: Compression) -> list[SimulatedWorld]:
    """Write ``out_dir``/<name>.mcap for every world (``workers`` at a time, the costliest
    first; each world depends on its own spec alone; chunks compressed by ``compression``:
    ``verdict.tuning.compression``) and the index (``tuning_index``) last."""
    from pipeline.sim.dataset import simulate_folder

    simulate_folder({w.name: w.spec for w in worlds}, tuning_index(worlds), out_dir, workers,
                    compression=compression)
    return worlds
