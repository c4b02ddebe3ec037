"""Simulated KITTI: the ``simulate_kitti`` stage's data set (pipeline/sim/kitti_world.py).

``simulate_kitti_set`` writes ``<out>/<NN>.mcap`` for every KITTI sequence named in the params
section ``simulate_kitti`` (HDL-64E scans ray-cast along the sequence's ground-truth trajectory
``<trajectories>/NN.txt`` through its simulated-KITTI world, environment labels per frame) and
``<out>/index.json`` ({"train": [...], "validation": [...]}), the layout of the ``ingest`` and
``simulate`` stages. Without a trajectories folder it writes an empty index.
"""

from __future__ import annotations

import logging
from pathlib import Path

from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.errors import InputError
from pipeline.io_utils import output_folder
from pipeline.sequence_index import check_split, write_index
from pipeline.sim.dataset import simulate_all
from pipeline.sim.effects import KITTI_EFFECTS, SensorEffects
from pipeline.sim.kitti_world import SCHEDULES, KittiWorldEffects
from pipeline.sim.sensors import SensorModel, SensorName, get_sensor
from pipeline.sim.simulate import MotionMode, SimSummary, derive_seed

log = logging.getLogger(__name__)


class SimulateKittiSection(Section):
    """params.yaml ``simulate_kitti``: simulated KITTI sequences and their split.

    trajectories: folder of KITTI ground-truth files NN.txt (and NN_times.txt); null = none.
    start / end: frame window of every sequence (KITTI frame numbers, end inclusive, cut to the
    sequence's length); windows: [[NN, start, end], ...] for single sequences (override
    start/end; a list, not a mapping: `dvc exp run -S` merges mappings and reads the key 10 as a
    number, which DVC cannot sort beside "09").
    effects: the sensor's physical effects (``SensorEffects``, docs/simulator.md); world: what
    the world adds (``KittiWorldEffects``: ground roughness, road camber, traffic); seed: null =
    derived from base.seed and the sequence name; motion: how scans follow the motion
    (``MotionMode``; KITTI's files are swept and compensated with the vehicle's poses);
    workers: sequences simulated at a time (processes; the output does not depend on it).
    """

    trajectories: str | None = None
    train: list[str] = Field(default_factory=list)
    validation: list[str] = Field(default_factory=list)
    start: int | None = Field(None, ge=0)
    end: int | None = Field(None, ge=0)
    windows: list[tuple[str, int, int]] = Field(default_factory=list)
    sensor: SensorName = "hdl64"
    effects: SensorEffects = Field(
        default_factory=lambda: SensorEffects.model_validate(KITTI_EFFECTS))
    world: KittiWorldEffects = Field(
        default_factory=lambda: KittiWorldEffects.model_validate({}))
    seed: int | None = Field(None, ge=0)
    motion: MotionMode = "compensated"
    workers: int = Field(2, ge=1)

    @field_validator("train", "validation")
    @classmethod
    def _known(cls, v: list[str]) -> list[str]:
        bad = [s for s in v if s not in SCHEDULES]
        if bad:
            raise ValueError(f"unknown KITTI sequence {bad[0]!r} (known: {', '.join(SCHEDULES)})")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> SimulateKittiSection:
        check_split("trajectories", self.trajectories, self.train, self.validation)
        if self.start is not None and self.end is not None and self.end <= self.start:
            raise ValueError(f"end must be > start, got (start={self.start}, end={self.end})")
        names = [name for name, _, _ in self.windows]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"sequence {twice[0]!r} has two windows, got {self.windows}")
        for name, a, b in self.windows:
            if name not in [*self.train, *self.validation]:
                raise ValueError(f"window of {name!r}, which is in neither train nor validation")
            if not 0 <= a < b:
                raise ValueError(f"window of {name!r} must be [start, end] with 0 <= start < end, "
                                 f"got [{a}, {b}]")
        return self

    def window(self, name: str, frames: int) -> tuple[int, int]:
        """(first, last) frame (inclusive) of sequence ``name`` of ``frames`` frames;
        InputError when the window does not overlap the sequence."""
        default = (self.start or 0, frames - 1 if self.end is None else self.end)
        first, last = {n: (a, b) for n, a, b in self.windows}.get(name, default)
        last = min(last, frames - 1)
        if first >= last:
            raise InputError(f"sequence {name} has {frames} frames, the window starts at "
                             f"frame {first}")
        return first, last


def simulate_kitti_set(section: SimulateKittiSection, base_seed: int, out_dir: str | Path,
                       progress: bool = False) -> list[SimSummary]:
    """Simulate the configured sequences into ``out_dir`` (module docstring)."""
    out_dir = Path(out_dir)
    output_folder(out_dir)
    if section.trajectories is None:
        log.info("simulate_kitti: no trajectories configured, writing an empty data set")
    bars = progress and section.workers == 1
    jobs = [(section, name, base_seed, out_dir / f"{name}.mcap", bars)
            for name in [*section.train, *section.validation]]
    done = simulate_all(simulate_kitti_sequence, jobs, [job[3] for job in jobs], section.workers,
                        not bars)
    write_index(out_dir, {"train": list(section.train), "validation": list(section.validation)})
    return done


def simulate_kitti_sequence(section: SimulateKittiSection, name: str, base_seed: int,
                            out_path: Path, progress: bool = False) -> SimSummary:
    """One simulated KITTI sequence (its window) into ``out_path``."""
    from pipeline.sim.kitti import kitti_lidar_poses
    from pipeline.sim.kitti_world import build_kitti_world
    from pipeline.sim.simulate import sensor_extra, write_world

    assert section.trajectories is not None
    trajectory = Path(section.trajectories) / f"{name}.txt"
    frames = len(kitti_lidar_poses(trajectory)[0])
    first, last = section.window(name, frames)
    seed = derive_seed(base_seed if section.seed is None else section.seed, name)
    world = build_kitti_world(trajectory, name, seed, first, last, section.world)
    sensor = kitti_sensor(section)
    extra = {"world": "kitti", "kitti_sequence": name, "first_frame": str(first),
             "last_frame": str(last), "seed": str(seed),
             "mesh_triangles": str(len(world.triangles))} | sensor_extra(sensor, section.motion)
    summary = write_world(world, sensor, seed, out_path, name,
                          f"simulation:kitti {trajectory.name}", extra, progress, section.motion)
    log.info("%s: frames %d-%d, %.0f m, %s", name, first, last, summary.length_m,
             ", ".join(f"{x.label} {x.start}-{x.end}" for x in summary.labels))
    return summary


def kitti_sensor(section: SimulateKittiSection) -> SensorModel:
    """The sensor model the section configures."""
    return get_sensor(section.sensor, section.effects)
