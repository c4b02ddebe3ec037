"""A suite world held in memory (studies/suites/loaded.py): the same scans, poses and labels,
and the same runs, as the world written to an MCAP and read back (the path it replaced)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.odometry.ndt import SPACE
from pipeline.sequence import Scan, SequenceReader
from pipeline.sim.dataset import SimulateSection
from pipeline.sim.simulate import simulate_scans, simulate_sequence
from studies.suites.loaded import LoadedWorld
from studies.suites.worlds import SimulatedWorld
from studies.verdict.section import VerdictSection
from studies.verdict.worlds import sensor_template, suite_worlds

FRAMES = 40


def _world(sensor: str) -> SimulatedWorld:
    worlds = suite_worlds(VerdictSection(), "id", sensor_template(SimulateSection(), 42))
    w = next(w for w in worlds if w.spec.sensor == sensor)
    return replace(w, spec=replace(w.spec, frames=FRAMES))


def _loaded(name: str, scans: list[Scan], labels: list[str]) -> LoadedWorld:
    return LoadedWorld(name, scans, labels, "ndt", None, SPACE, 5.0, 100.0)


def test_a_world_in_memory_is_the_world_its_mcap_gives_back(tmp_path: Path) -> None:
    world = _world("hdl32")
    memory = simulate_scans(world.spec)
    path = simulate_sequence(world.spec, tmp_path / f"{world.name}.mcap", name=world.name).path
    with SequenceReader(path) as reader:
        decoded = list(reader)
        labels = [reader.info.label_of(i) or "" for i in range(len(reader))]
    assert memory.labels == labels and len(set(labels)) > 1  # the world's segments, per frame
    assert len(memory.scans) == len(decoded) == FRAMES
    for a, b in zip(memory.scans, decoded, strict=True):
        assert (a.frame, a.stamp_ns) == (b.frame, b.stamp_ns)
        assert a.points_lidar.dtype == b.points_lidar.dtype == np.float32
        np.testing.assert_array_equal(a.points_lidar, b.points_lidar)
        assert a.time_s is not None  # swept scans (the training sensor model's motion)
        np.testing.assert_array_equal(a.time_s, b.time_s)
        np.testing.assert_array_equal(a.T_world_lidar, b.T_world_lidar)  # as recorded, to the bit

    params = {"resolution": 1.5, "keyframe_interval": 4.0}
    in_memory = _loaded(world.name, memory.scans, memory.labels).run(params, 0, 0.005)
    from_mcap = _loaded(world.name, decoded, labels).run(params, 0, 0.005)
    assert not in_memory[1] and not from_mcap[1]
    assert np.isfinite(in_memory[0]).any()
    np.testing.assert_array_equal(in_memory[0], from_mcap[0])  # the same runs, to the bit


def test_a_world_without_ground_truth_or_labels_is_refused() -> None:
    world = _world("hdl32")
    sim = simulate_scans(replace(world.spec, frames=3))
    with pytest.raises(InputError, match="3 scans, 2 labels"):
        _loaded(world.name, sim.scans, sim.labels[:2])
    sim.scans[1] = replace(sim.scans[1], T_world_lidar=None)
    with pytest.raises(InputError, match="frame 1 needs a ground-truth pose"):
        _loaded(world.name, sim.scans, sim.labels)


def test_a_run_that_jumps_further_than_the_worlds_limit_fails_at_the_penalty() -> None:
    """A recorded run's jump limit (a real run's own) fails a run as a trial fails: every
    scored start frame at the penalty. Without a limit the same run finishes."""
    world = _world("hdl32")
    sim = simulate_scans(replace(world.spec, frames=20))
    params = {"resolution": 1.5, "keyframe_interval": 4.0}
    free = LoadedWorld(world.name, sim.scans, sim.labels, "ndt", None, SPACE, 5.0, 100.0)
    t_err, failed = free.run(params, 0, 0.005)
    assert not failed and np.nanmax(t_err) < 100.0
    steps_m = np.linalg.norm(np.diff(free.gt[:, :3, 3], axis=0), axis=1)
    tight = LoadedWorld(world.name, sim.scans, sim.labels, "ndt", None, SPACE, 5.0, 100.0,
                        jump_limit_m=float(steps_m.max()) / 2)
    t_err, failed = tight.run(params, 0, 0.005)
    assert failed
    assert set(t_err[np.isfinite(t_err)]) == {100.0}
