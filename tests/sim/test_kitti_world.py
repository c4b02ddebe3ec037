"""Simulated KITTI: environment schedules, labels, determinism, window independence, the
environments' structure, and the ``simulate-kitti-set`` stage command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from pipeline.errors import ConfigError
from pipeline.sequence import SequenceReader
from pipeline.sim.effects import SensorEffects
from pipeline.sim.kitti_world import (
    ENVIRONMENTS,
    SCHEDULES,
    build_kitti_world,
    change_window,
    frame_environments,
)
from pipeline.sim.raycast import Raycaster
from pipeline.sim.sensors import get_sensor
from stages.cli import main

FRAMES = {"00": 4541, "01": 1101, "02": 4661, "03": 801, "04": 271, "05": 2761, "06": 1101,
          "07": 1101, "08": 4071, "09": 1591, "10": 1201}


def test_every_sequence_has_a_schedule_from_its_first_frame() -> None:
    assert set(SCHEDULES) == set(FRAMES)
    for name, schedule in SCHEDULES.items():
        firsts = [f for f, _ in schedule]
        assert firsts[0] == 0 and firsts == sorted(set(firsts)) and firsts[-1] < FRAMES[name]
        envs = frame_environments(name, FRAMES[name])
        assert len(envs) == FRAMES[name] and set(envs) <= set(ENVIRONMENTS)
        for first, env in schedule:
            assert envs[first] == env
    assert set(frame_environments("01", 1101)) == {"highway"}  # the paper's odd one out
    train = {e for n in ("00", "01", "02", "03", "04", "05") for e in frame_environments(n, 5000)}
    test = {e for n in ("06", "07", "08", "09", "10") for e in frame_environments(n, 5000)}
    assert train == set(ENVIRONMENTS) and test == {"urban", "residential", "rural"}
    with pytest.raises(ConfigError, match="no environment schedule for KITTI sequence '11'"):
        frame_environments("11", 10)


def test_change_windows_show_the_first_change_of_environment() -> None:
    for name, frames in FRAMES.items():
        first, last = change_window(name, frames, 250)
        assert last - first == 249 and first >= 0 and last < frames
        envs = frame_environments(name, frames)[first:last + 1]
        assert len(set(envs)) == min(2, len(SCHEDULES[name]))
    assert change_window("05", 2761, 250) == (600, 849)
    assert change_window("04", 271, 1000) == (0, 270)


def _noise_free_scan(world, k: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    sensor = get_sensor("hdl64", SensorEffects.ideal())
    pts = Raycaster(world.vertices, world.triangles, sensor, world.materials).scan(
        world.poses.T_world_lidar[k], np.random.default_rng(0))
    return pts[np.linalg.norm(pts[:, :3], axis=1) < 90.0]


def test_world_is_deterministic_and_independent_of_the_window(kitti_trajectories: Path) -> None:
    path = kitti_trajectories / "05.txt"
    a = build_kitti_world(path, "05", 7, 690, 710)
    again = build_kitti_world(path, "05", 7, 690, 710)
    assert np.array_equal(a.vertices, again.vertices)
    assert np.array_equal(a.triangles, again.triangles)
    other = build_kitti_world(path, "05", 7, 700, 730)  # frame 705 is in both windows
    assert np.array_equal(a.poses.T_world_lidar[15], other.poses.T_world_lidar[5])
    pa, pb = _noise_free_scan(a, 15), _noise_free_scan(other, 5)
    assert len(pa) == len(pb) and np.allclose(pa, pb, atol=1e-3)
    seed = build_kitti_world(path, "05", 8, 690, 710)
    assert len(seed.triangles) != len(a.triangles) or not np.array_equal(seed.vertices,
                                                                         a.vertices)
    # the window crosses the schedule's change from residential to urban at frame 700
    assert a.poses.frame_labels == ["residential"] * 10 + ["urban"] * 11


def _near_structure(path: Path, name: str, frame: int) -> float:
    """Share of the returns of a noise-free scan that hit something standing more than 0.5 m
    above the road within 30 m of the sensor (walls, cars, hedges, trees, rails)."""
    world = build_kitti_world(path / f"{name}.txt", name, 1, frame, frame + 1)
    pts = _noise_free_scan(world, 0)
    near = np.linalg.norm(pts[:, :2], axis=1) < 30.0
    return float((near & (pts[:, 2] > 0.5 - 1.73)).mean())


def test_environments_differ_as_kitti_does(kitti_trajectories: Path) -> None:
    """Urban canyons close the view, residential streets less so, the country road and the
    highway (sequence 01) leave it open: the structure the odometry has to work with. (The
    highway's embankments carry shrubs 10-20 m off the road since issue 30: less open than the
    country road, still less closed than a residential street.)"""
    share = {env: _near_structure(kitti_trajectories, name, frame) for env, name, frame in (
        ("urban", "07", 100), ("residential", "05", 200), ("rural", "04", 100),
        ("highway", "01", 300))}
    assert share["urban"] > share["residential"] > max(share["rural"], share["highway"])
    assert share["rural"] < share["residential"] / 2


def test_simulate_kitti_set_writes_labelled_hdl64_sequences(tmp_path: Path,
                                                           kitti_trajectories: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"base": {"seed": 3}, "simulate_kitti": {
        "trajectories": str(kitti_trajectories), "train": ["05"], "validation": ["04"],
        "start": 697, "end": 702, "windows": [["04", 268, 280]], "motion": "sweep"}}))
    out = tmp_path / "sim"
    result = CliRunner().invoke(main, ["simulate-kitti-set", "--params", str(params),
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "index.json").read_text()) == {"train": ["05"],
                                                            "validation": ["04"]}
    with SequenceReader(out / "05.mcap") as r:
        assert len(r) == 6 and r.info.sensor == "Velodyne HDL-64E"
        assert [(x.start, x.end, x.label) for x in r.info.labels] == [
            (0, 2, "residential"), (3, 5, "urban")]
        assert r.info.extra["first_frame"] == "697" and r.ground_truth() is not None
        scan = next(iter(r))
        assert len(scan.points_lidar) > 50_000
        assert scan.time_s is not None and 0.0 <= scan.time_s.min() < scan.time_s.max() < 0.1
    with SequenceReader(out / "04.mcap") as r:  # the window is cut to the sequence's end
        assert len(r) == 3 and r.info.labels[0].label == "rural"


@pytest.mark.parametrize(("section", "message"), [
    ({"trajectories": "x", "train": []},
     "simulate_kitti: train must name KITTI sequences when trajectories is set"),
    ({"train": ["12"]}, "simulate_kitti.train: unknown KITTI sequence '12'"),
    ({"trajectories": "x", "train": ["01"], "validation": ["01"]},
     "sequence '01' is in both train and validation"),
    ({"trajectories": "x", "train": ["01"], "windows": [["02", 0, 5]]},
     "window of '02', which is in neither train nor validation"),
    ({"trajectories": "x", "train": ["01"], "windows": [["01", 5, 5]]},
     "window of '01' must be [start, end]"),
    ({"trajectories": "x", "train": ["01"], "windows": [["01", 0, 5], ["01", 6, 9]]},
     "'01' has two windows"),
    ({"train": ["01"]}, "train and validation name no sequences while trajectories is not set"),
])
def test_simulate_kitti_set_refuses_bad_params(tmp_path: Path, section: dict,
                                               message: str) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"simulate_kitti": section}))
    result = CliRunner().invoke(main, ["simulate-kitti-set", "--params", str(params),
                                       "--out", str(tmp_path / "sim")])
    assert result.exit_code == 1 and result.output.count("\n") == 1
    assert message in result.output
    assert not (tmp_path / "sim").exists()


def test_simulate_kitti_set_without_trajectories_writes_an_empty_index(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"simulate_kitti": {}}))
    result = CliRunner().invoke(main, ["simulate-kitti-set", "--params", str(params),
                                       "--out", str(tmp_path / "sim")])
    assert result.exit_code == 0
    assert json.loads((tmp_path / "sim" / "index.json").read_text()) == {
        "train": [], "validation": []}
