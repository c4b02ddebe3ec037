"""The toy data set of params.yaml: training worlds and composite validation sequences."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator

from pipeline.config import Section
from pipeline.io_utils import output_folder
from pipeline.progress import PROGRESS
from pipeline.sequence import Compression
from pipeline.sequence_index import write_index
from pipeline.sim.effects import SensorEffects
from pipeline.sim.route import LABELS
from pipeline.sim.sensors import SensorName
from pipeline.sim.simulate import (
    MotionMode,
    SimSpec,
    SimSummary,
    derive_seed,
    simulate_sequence,
)
from pipeline.sim.worlds import MAX_FRAMES, WORLDS

log = logging.getLogger(__name__)


class SimulateSection(Section):
    """params.yaml section ``simulate``. Seeds derive from ``base.seed`` and the sequence name
    unless ``seed`` is given here; ``workers``: sequences simulated at a time (processes; the
    output does not depend on it). ``sensor``: of the validation sequences, and of the
    training ones unless ``train_sensors`` is given: then training sequence i of a world
    (``cave_i``) uses ``train_sensors[i % len(train_sensors)]``. ``effects``: the sensor's
    physical effects (``SensorEffects``, docs/simulator.md); ``motion``: how scans follow the
    sensor's motion (``MotionMode``)."""

    seed: int | None = Field(None, ge=0)
    sensor: SensorName = "hdl32"
    train_sensors: list[SensorName] = Field(default_factory=list)
    effects: SensorEffects = Field(default_factory=lambda: SensorEffects.model_validate({}))
    motion: MotionMode = "sweep"
    train: dict[str, int] = Field(default_factory=lambda: {"cave": 4, "street": 4})
    train_frames: int = Field(350, ge=10, le=MAX_FRAMES)
    validation_count: int = Field(1, ge=0)
    validation_frames: int = Field(1050, ge=30, le=MAX_FRAMES)
    validation_segments: list[str] = Field(default_factory=lambda: list(LABELS), min_length=1)
    workers: int = Field(2, ge=1)

    @field_validator("train")
    @classmethod
    def _train_worlds(cls, v: dict[str, int]) -> dict[str, int]:
        for world, count in v.items():
            if world not in WORLDS:
                raise ValueError(f"unknown world {world!r} (known: {', '.join(WORLDS)})")
            if count < 0:
                raise ValueError(f"count of {world} must be >= 0, got {count}")
        if sum(v.values()) < 1:
            raise ValueError("needs at least one training sequence")
        return v

    @field_validator("validation_segments")
    @classmethod
    def _segments(cls, v: list[str]) -> list[str]:
        bad = [s for s in v if s not in LABELS]
        if bad:
            raise ValueError(f"unknown segment {bad[0]!r} (known: {', '.join(LABELS)})")
        return v


def dataset_specs(section: SimulateSection, base_seed: int) -> dict[str, tuple[str, SimSpec]]:
    """name -> (split, SimSpec) of every sequence of the data set, in a stable order."""
    seed0 = base_seed if section.seed is None else section.seed

    def spec(world: str, name: str, frames: int, segments: tuple[str, ...] = (),
             sensor: str = section.sensor) -> SimSpec:
        return SimSpec(world, derive_seed(seed0, name), frames, sensor,
                       segments or tuple(LABELS), section.effects, section.motion)

    out: dict[str, tuple[str, SimSpec]] = {}
    sensors = section.train_sensors or [section.sensor]
    for world, count in section.train.items():
        for i in range(count):
            out[f"{world}_{i}"] = ("train", spec(world, f"{world}_{i}", section.train_frames,
                                                 sensor=sensors[i % len(sensors)]))
    for i in range(section.validation_count):
        name = f"composite_{i}"
        out[name] = (
            "validation",
            spec("composite", name, section.validation_frames, tuple(section.validation_segments)),
        )
    return out


def simulate_set(
    section: SimulateSection, base_seed: int, out_dir: str | Path, progress: bool = False
) -> list[SimSummary]:
    """Write ``out_dir``/<name>.mcap for every sequence and ``out_dir``/index.json
    ({"train": [...], "validation": [...]}); returns what was written, in index order
    (``simulate_folder``, ``section.workers`` at a time)."""
    specs = dataset_specs(section, base_seed)
    index: dict[str, list[str]] = {"train": [], "validation": []}
    for name, (split, _) in specs.items():
        index[split].append(name)
    return simulate_folder({name: spec for name, (_, spec) in specs.items()}, index, out_dir,
                           section.workers, progress)


def simulate_folder(specs: Mapping[str, SimSpec], index: Mapping[str, list[str]],
                    out_dir: str | Path, workers: int, progress: bool = False,
                    compression: Compression = "zstd") -> list[SimSummary]:
    """A sequences folder: ``out_dir``/<name>.mcap for every spec (chunks compressed by
    ``compression``), then ``index`` (split -> names) as its index.json, written last; returns
    what was written, in ``specs``' order.

    ``workers`` sequences at a time in spawned processes, the costliest first
    (``pipeline.executor.costliest_first``); each sequence depends only on its own spec, so the
    files are the same whatever ``workers``. ``progress``: a bar per sequence (one worker only); a
    log line per finished sequence otherwise."""
    from pipeline.executor import costliest_first

    out = output_folder(Path(out_dir))
    bars = progress and workers == 1
    jobs = [(spec, out / f"{name}.mcap", name, bars, compression)
            for name, spec in specs.items()]
    summaries = simulate_all(simulate_sequence, jobs, [job[1] for job in jobs], workers,
                             not bars, costliest_first([s.rays() for s in specs.values()]))
    write_index(out, dict(index))
    return summaries


def simulate_all(fn: Callable[..., SimSummary], jobs: Sequence[tuple[Any, ...]],
                 outputs: Sequence[Path], workers: int, log_lines: bool,
                 order: Sequence[int] | None = None) -> list[SimSummary]:
    """``[fn(*job) for job in jobs]`` (job i writes ``outputs[i]``), ``workers`` at a time in
    spawned processes, started in ``order`` (``pipeline.executor.map_in_processes``); with
    ``log_lines`` a progress line per finished sequence. On a failure (or Ctrl-C) the other
    workers are killed, and the temporaries of their unfinished outputs removed."""
    from pipeline.executor import map_in_processes
    from pipeline.io_utils import remove_stale_temps

    t0 = time.monotonic()
    finished = 0

    def done(i: int, summary: SimSummary) -> None:
        nonlocal finished
        finished += 1
        if log_lines:
            PROGRESS.info("simulate [%d/%d] %s: %d frames, %.0f m, %.0f s", finished, len(jobs),
                          summary.name, summary.frames, summary.length_m, time.monotonic() - t0)

    try:
        return map_in_processes(fn, jobs, workers, done, order)
    except BaseException:
        for path in outputs:  # the workers are gone: what they were writing is stale
            remove_stale_temps(path)
        raise
