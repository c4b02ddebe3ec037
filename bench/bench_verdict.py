"""The verdict's suite worlds: loading one in memory against the MCAP path it replaced (issue 29,
`make verdict`'s time).

Rows, per sensor of the in-distribution suites (HDL-32E, HDL-64E): milliseconds a frame to have
a world's scans ready to run, for its first ADAPTUNE_BENCH_VERDICT_FRAMES frames (default 150)
of the first world of that sensor in the id test suite. Ours: ``simulate_scans`` (the scans
simulated straight into memory, ``studies.suites.runner.load_world``); reference, in the same
run: ``simulate_sequence`` into an MCAP, then ``SequenceReader`` decoding it (what a suite world
cost before, and what ``simulate-set`` and ``tuning-suite`` still do for worlds they keep).
Both then warm the adapter and run the settings, which cost the same either way. Wall time,
best of 2, on the whole machine (the ray caster uses every core, as in a suite's worker).
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from common import Row, size

if TYPE_CHECKING:
    from pipeline.sim.simulate import SimSpec


def run() -> list[Row]:
    from pipeline.sim.dataset import SimulateSection
    from studies.verdict.section import VerdictSection
    from studies.verdict.worlds import sensor_template, suite_worlds

    frames = int(os.environ.get("ADAPTUNE_BENCH_VERDICT_FRAMES", size("150", "3")))
    worlds = suite_worlds(VerdictSection(), "id", sensor_template(SimulateSection(), 42))
    rows = []
    for sensor in ("hdl32", "hdl64"):
        world = next(w for w in worlds if w.spec.sensor == sensor)
        spec = replace(world.spec, frames=frames)
        memory = _best(_in_memory, spec, world.name) / frames
        mcap = _best(_through_mcap, spec, world.name) / frames
        rows.append(Row(f"verdict world ready, ms/frame ({sensor}, {world.name}, {frames} "
                        f"frames)", 1000 * memory, "ms/frame",
                        f"through an MCAP {1000 * mcap:.1f} ms/frame (x{memory / mcap:.2f})",
                        "< the MCAP path"))
    return rows


def _best(fn: Callable[[SimSpec, str], int], spec: SimSpec, name: str, repeat: int = 2) -> float:
    """Best wall time [s] of ``repeat`` calls ``fn(spec, name)`` (one in a smoke run)."""
    best = float("inf")
    for _ in range(size(repeat, 1)):
        t0 = time.perf_counter()
        fn(spec, name)
        best = min(best, time.perf_counter() - t0)
    return best


def _in_memory(spec: SimSpec, name: str) -> int:
    from pipeline.sim.simulate import simulate_scans

    return len(simulate_scans(spec).scans)


def _through_mcap(spec: SimSpec, name: str) -> int:
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import simulate_sequence

    with tempfile.TemporaryDirectory() as tmp:
        path = simulate_sequence(spec, Path(tmp) / f"{name}.mcap", name=name).path
        with SequenceReader(path) as reader:
            return len(list(reader))
