"""Simulated worlds: determinism, ground truth consistent with the rays, labels, sensors."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.errors import ConfigError
from pipeline.sequence import SequenceReader
from pipeline.sim.effects import SensorEffects
from pipeline.sim.raycast import Raycaster
from pipeline.sim.sensors import SENSORS, get_sensor
from pipeline.sim.simulate import (
    SimSpec,
    iter_scans,
    label_ranges,
    make_world,
    simulate_sequence,
    world_points,
)
from stages.cli import main
from studies.realism.statistics import ring_of_points

SENSOR_FACTS = {  # beams, lowest and highest elevation [deg]
    "hdl32": (32, -30.67, 10.67),
    "hdl64": (64, -24.965, 1.933),  # KITTI's unit (pipeline/sim/kitti_sensor.py)
    "vlp16": (16, -15.0, 15.0),
}
IDEAL = SensorEffects.ideal()


def _points(path: Path) -> list[np.ndarray]:
    with SequenceReader(path) as r:
        return [s.points_lidar for s in r]


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path: Path) -> None:
    a, b, c = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    simulate_sequence(SimSpec("street", 7, 4), a)
    simulate_sequence(SimSpec("street", 7, 4), b)
    simulate_sequence(SimSpec("street", 8, 4), c)
    pa, pb, pc = _points(a), _points(b), _points(c)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(pa, pb, strict=True))
    assert pa[0].tobytes() != pc[0].tobytes()
    with SequenceReader(a) as ra, SequenceReader(b) as rb:
        np.testing.assert_array_equal(ra.ground_truth(), rb.ground_truth())
        np.testing.assert_array_equal(ra.stamps_ns, rb.stamps_ns)


@pytest.mark.parametrize("world", ["cave", "open", "street"])
def test_scan_lands_on_the_mesh_by_its_ground_truth(world: str) -> None:
    spec = SimSpec(world, 3, 60, effects=SensorEffects.ideal(range_noise_m=0.02))
    w = make_world(spec)
    caster = Raycaster(w.vertices, w.triangles, spec.sensor_model(), w.materials)
    for scan in iter_scans(w, spec.sensor_model(), spec.seed, range(0, 60, 29)):
        d = caster.distance_to_mesh(world_points(scan))
        assert len(d) > 10_000
        assert np.median(d) < 0.025, np.median(d)
        assert np.quantile(d, 0.999) < 0.1 and d.max() < 0.15
        # a pose 20 cm off in every axis does not land on the mesh
        T = scan.T_world_lidar.copy()
        T[:3, 3] += 0.2
        moved = scan.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        assert np.median(caster.distance_to_mesh(moved)) > 0.08


def test_noise_free_scan_is_exact() -> None:
    spec = SimSpec("cave", 4, 10, effects=IDEAL)
    w = make_world(spec)
    scan = next(iter_scans(w, spec.sensor_model(), 4, range(5, 6)))
    d = Raycaster(w.vertices, w.triangles, spec.sensor_model()).distance_to_mesh(world_points(scan))
    assert d.max() < 2e-3


def test_composite_labels_cover_every_frame_in_order(tmp_path: Path) -> None:
    out = tmp_path / "comp.mcap"
    summary = simulate_sequence(SimSpec("composite", 5, 150), out)
    with SequenceReader(out) as r:
        labels = r.info.labels
        assert [x.label for x in labels] == ["cave", "open", "street"]
        assert labels[0].start == 0 and labels[-1].end == len(r) - 1 == 149
        assert all(b.start == a.end + 1 for a, b in itertools.pairwise(labels))
        assert all(r.info.label_of(k) is not None for k in range(len(r)))
        assert all(x.end - x.start + 1 >= 25 for x in labels)
    assert summary.labels == labels


def test_composite_follows_the_given_segment_order() -> None:
    w = make_world(SimSpec("composite", 5, 90, segments=("street", "cave")))
    ranges = label_ranges(w.poses.frame_labels)
    assert [x.label for x in ranges] == ["street", "cave"]
    assert ranges[-1].end == 89


def test_a_composite_world_shorter_than_its_segments_is_finite() -> None:
    """Two frames through four segments: the cave is one route sample between two others
    (its floor's slope once divided by its zero length, giving NaN poses and an SVD error)."""
    w = make_world(SimSpec("composite", 1634085409, 2, "hdl64",
                           segments=("open", "street", "cave", "open")))
    assert np.isfinite(w.poses.T_world_lidar).all() and np.isfinite(w.vertices).all()
    assert len(list(iter_scans(w, get_sensor("hdl64"), 1))) == 2


def test_speeds_fit_the_world() -> None:
    for world, lo, hi in (("cave", 0.8, 2.0), ("street", 3.0, 10.0)):
        T = make_world(SimSpec(world, 2, 200)).poses.T_world_lidar
        v = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1) * 10.0
        assert lo < np.median(v) < hi, (world, np.median(v))
        assert v.max() < hi * 1.2


@pytest.mark.parametrize("name", sorted(SENSOR_FACTS))
def test_sensor_beams_and_vertical_field_of_view(name: str) -> None:
    beams, lo, hi = SENSOR_FACTS[name]
    sensor = get_sensor(name, IDEAL)
    assert sensor.beams == beams and sensor.rate_hz == 10.0
    assert sensor.vertical_fov_deg == pytest.approx((lo, hi), abs=2e-3)
    d = sensor.ray_directions()
    assert d.shape == (beams * sensor.azimuths, 3)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    # in a cave every beam hits: the returns form exactly `beams` rings, each at its laser's
    # elevation seen from the laser's own origin
    w = make_world(SimSpec("cave", 1, 3, sensor=name))
    pts = Raycaster(w.vertices, w.triangles, sensor, w.materials).scan(
        w.poses.T_world_lidar[1], np.random.default_rng(0)
    )
    ring = ring_of_points(pts)
    assert ring.max() + 1 == beams
    z = pts[:, 2] - sensor.laser_heights()[ring]
    el = np.degrees(np.arctan2(z, np.hypot(pts[:, 0], pts[:, 1])))
    np.testing.assert_allclose(el, np.array(sensor.elevations_deg)[ring], atol=1e-3)
    assert len(pts) > 0.9 * beams * sensor.azimuths


def test_dropout_and_noise_settings() -> None:
    s = get_sensor("hdl32", IDEAL)
    assert get_sensor("hdl32").effects == SensorEffects.model_validate({})
    w = make_world(SimSpec("cave", 1, 3))
    full = Raycaster(w.vertices, w.triangles, s.with_noise(dropout=0.0), w.materials).scan(
        w.poses.T_world_lidar[1], np.random.default_rng(0)
    )
    half = Raycaster(w.vertices, w.triangles, s.with_noise(dropout=0.5), w.materials).scan(
        w.poses.T_world_lidar[1], np.random.default_rng(0)
    )
    assert 0.45 < len(half) / len(full) < 0.55
    with pytest.raises(ConfigError, match="dropout"):
        s.with_noise(dropout=1.5)
    with pytest.raises(ConfigError, match="unknown sensor"):
        get_sensor("ouster")
    assert set(SENSORS) == set(SENSOR_FACTS)


def test_simulate_any_kitti_window_in_one_command(kitti_trajectories: Path, kitti_root: Path,
                                                   tmp_path: Path) -> None:
    """``simulate --world kitti``: frame k of the output is frame START + k of the pose file
    (its lidar pose through KITTI's calibration), at KITTI's stamps from NN_times.txt, in the
    simulated-KITTI world of sequence NN (its environments)."""
    from pipeline.geometry import inv_se3
    from pipeline.kitti_calib import calib_for_pose_file

    path, out = kitti_trajectories / "04.txt", tmp_path / "k.mcap"
    r = CliRunner().invoke(main, ["simulate", "--world", "kitti", "--kitti-trajectory",
                                  str(path), "--start", "100", "--frames", "3", "--sensor",
                                  "hdl64", "--out", str(out)])
    assert r.exit_code == 0, r.output
    rows = np.loadtxt(path)[100:103]
    P = np.tile(np.eye(4), (3, 1, 1))
    P[:, :3, :4] = rows.reshape(-1, 3, 4)
    Tr = calib_for_pose_file(path)
    times = np.loadtxt(kitti_trajectories / "04_times.txt")[100:103]
    with SequenceReader(out) as seq:
        np.testing.assert_allclose(seq.ground_truth(), inv_se3(Tr) @ P @ Tr, atol=1e-6)
        np.testing.assert_array_equal(seq.stamps_ns,
                                      1_000_000_000 + np.round(times * 1e9).astype(np.int64))
        assert seq.info.sensor == "Velodyne HDL-64E"
        assert [x.label for x in seq.info.labels] == ["rural"]
        assert seq.info.extra["first_frame"] == "100" and seq.info.extra["motion"] == "compensated"
        scan = seq[1]
        assert len(scan.points_lidar) > 80_000 and scan.time_s is None  # KITTI's: compensated
    # Tr of sequence 04 matches the dataset's own calib.txt
    calib = (kitti_root / "sequences" / "04" / "calib.txt").read_text().splitlines()
    tr = next(line for line in calib if line.startswith("Tr:")).split()[1:]
    np.testing.assert_allclose(Tr[:3, :4].ravel(), np.array(tr, float))


def test_cli_simulate_and_bad_input(tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    r = CliRunner().invoke(
        main,
        [
            "simulate",
            "--world",
            "open",
            "--seed",
            "2",
            "--frames",
            "3",
            "--sensor",
            "vlp16",
            "--out",
            str(out),
        ],
    )
    assert r.exit_code == 0, r.output
    with SequenceReader(out) as seq:
        assert len(seq) == 3 and seq.info.sensor == "Velodyne VLP-16"
        assert seq.info.labels[0].label == "open"
    for args, msg in (
        (["--world", "composite", "--segments", "cave,lava"], "segments must be"),
        (["--frames", "1"], "frames must be in [2, 100000]"),
        (["--world", "cave", "--noise", "-1"], "simulate.effects.range_noise_m"),
        (["--world", "open", "--kitti-trajectory", str(tmp_path / "04.txt")],
         "needs --world kitti"),
        (["--world", "kitti"], "--world kitti needs --kitti-trajectory"),
        (["--world", "kitti", "--kitti-trajectory", str(tmp_path / "04.txt")], "no such KITTI"),
    ):
        bad = tmp_path / "bad.mcap"
        r = CliRunner().invoke(main, ["simulate", *args, "--out", str(bad)])
        assert r.exit_code == 1, (args, r.output)
        assert msg in r.output and "Traceback" not in r.output
        assert not bad.exists() and not list(tmp_path.glob("*.tmp*"))


def test_cli_simulate_set_writes_sequences_and_index(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(
        "base:\n  seed: 3\nsimulate:\n  train: {cave: 1, street: 1}\n"
        "  train_frames: 12\n  validation_frames: 30\n"
    )
    out = tmp_path / "seq"
    r = CliRunner().invoke(main, ["simulate-set", "--params", str(params), "--out", str(out)])
    assert r.exit_code == 0, r.output
    index = json.loads((out / "index.json").read_text())
    assert index == {"train": ["cave_0", "street_0"], "validation": ["composite_0"]}
    with SequenceReader(out / "composite_0.mcap") as seq:
        assert len(seq) == 30 and {x.label for x in seq.info.labels} == {"cave", "open", "street"}
    params.write_text("simulate:\n  train: {lava: 2}\n")
    r = CliRunner().invoke(
        main, ["simulate-set", "--params", str(params), "--out", str(tmp_path / "x")]
    )
    assert r.exit_code == 1 and "unknown world 'lava'" in r.output


def test_cli_plot_world(tmp_path: Path) -> None:
    out = tmp_path / "w.png"
    r = CliRunner().invoke(
        main, ["plot-world", "--world", "composite", "--frames", "60", "--out", str(out)]
    )
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_spec_of_a_simulated_sequence_rebuilds_its_world(tmp_path: Path) -> None:
    from pipeline.sequence import SequenceInfo
    from pipeline.sim.simulate import spec_of

    spec = SimSpec("composite", 5, 40, "vlp16", ("street", "cave"),
                   SensorEffects.ideal(range_noise_m=0.03, dropout=0.02), "none")
    simulate_sequence(spec, tmp_path / "c.mcap")
    with SequenceReader(tmp_path / "c.mcap") as reader:
        assert spec_of(reader.info) == spec
    assert spec_of(SequenceInfo(name="04", source="kitti:04", frame_count=10)) is None
