"""Each sensor and world effect of the simulator (docs/simulator.md) is switchable and does what
it claims, measured on small synthetic scenes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim import kitti_sensor, meshes
from pipeline.sim.effects import SensorEffects
from pipeline.sim.materials import Material
from pipeline.sim.raycast import Raycaster
from pipeline.sim.route import Route
from pipeline.sim.sensors import get_sensor
from pipeline.sim.traffic import Traffic

HOME = np.eye(4)


def _scene(*parts: tuple[np.ndarray, np.ndarray, int]) -> tuple[np.ndarray, np.ndarray,
                                                                 np.ndarray]:
    mb = meshes.MeshBuilder()
    for v, t, m in parts:
        mb.add(v, t, m)
    v, t = mb.build()
    return v, t, mb.materials()


def _wall(x: float, half: float = 40.0, tilt_deg: float = 0.0, y0: float = 0.0,
          material: int = Material.BUILDING) -> tuple[np.ndarray, np.ndarray, int]:
    """A square wall centred at (x, y0, 0), facing the sensor, turned by ``tilt_deg`` about z."""
    c, s = np.cos(np.deg2rad(tilt_deg)), np.sin(np.deg2rad(tilt_deg))
    corners = np.array([[0, -half, -half], [0, half, -half], [0, half, half], [0, -half, half]],
                       float)
    v = corners @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [x, y0, 0.0]
    return v, np.array([[0, 1, 2], [0, 2, 3]]), material


def _ground(z: float = -1.73, half: float = 200.0) -> tuple[np.ndarray, np.ndarray, int]:
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]]), Material.ROAD


def _scan(scene: tuple, effects: SensorEffects, sensor: str = "vlp16", seed: int = 0,
          T: np.ndarray = HOME) -> np.ndarray:
    v, t, m = scene
    return Raycaster(v, t, get_sensor(sensor, effects), m).scan(T, np.random.default_rng(seed))


def _range_error(scene: tuple, effects: SensorEffects, sensor: str = "vlp16") -> tuple:
    """(ranges, range error [m]) of the returns: noisy minus noise-free (same rays)."""
    clean = _scan(scene, SensorEffects.ideal())
    noisy = _scan(scene, effects)
    assert len(clean) == len(noisy)
    r0, r1 = (np.linalg.norm(p[:, :3], axis=1) for p in (clean, noisy))
    return r0, r1 - r0


def test_range_noise_grows_with_distance() -> None:
    effects = SensorEffects.ideal(range_noise_m=0.01, range_noise_growth_m=0.05)
    near = _range_error(_scene(_wall(10.0)), effects)[1].std()
    far = _range_error(_scene(_wall(60.0, half=50.0)), effects)[1].std()
    assert near == pytest.approx(np.hypot(0.01, 0.05 * 0.1), rel=0.2)
    assert far > 2.5 * near
    off = _range_error(_scene(_wall(60.0, half=50.0)), SensorEffects.ideal())[1]
    assert np.abs(off).max() < 1e-4


def test_range_noise_grows_with_incidence() -> None:
    """The beam's footprint on an inclined wall spreads its ranges (divergence only)."""
    effects = SensorEffects.ideal(beam_divergence_mrad=3.0)
    facing = _range_error(_scene(_wall(20.0, half=3.0)), effects)[1]
    inclined = _range_error(_scene(_wall(20.0, half=3.0, tilt_deg=75.0)), effects)[1]
    assert inclined.std() > 5.0 * facing.std()


def test_incidence_and_reflectance_decide_returns() -> None:
    """At the same range, a wall turned away from the beam and a dark one return less often;
    without the detection model everything returns."""
    on = SensorEffects.ideal(detection_range_m=24.0)
    rate = {}
    for name, wall in (("facing", _wall(30.0, half=4.0)),
                       ("grazing", _wall(30.0, half=4.0, tilt_deg=80.0)),
                       ("dark", _wall(30.0, half=4.0, material=Material.ROAD))):
        all_rays = len(_scan(_scene(wall), SensorEffects.ideal()))
        rate[name] = len(_scan(_scene(wall), on)) / all_rays
    assert rate["facing"] > 0.85 and rate["grazing"] < rate["facing"] - 0.15
    assert rate["dark"] < rate["facing"] - 0.3


def test_per_laser_calibration_errors_and_jitter() -> None:
    """A laser's range offset shifts all its returns alike; elevation errors bend a flat
    ground; jitter scatters single firings. All reproducible from the unit seed."""
    room = _scene((*meshes.box(np.zeros(3), np.array([30.0, 30.0, 30.0]), 0.3),
                   Material.BUILDING))
    biased = _range_error(room, SensorEffects.ideal(laser_range_bias_m=0.05))[1]
    per_laser = biased.reshape(16, -1)  # vlp16: every ray hits the room, laser after laser
    assert np.ptp(per_laser, axis=1).max() < 1e-4 and per_laser[:, 0].std() > 0.02
    ground = _scene(_ground())
    flat = _scan(ground, SensorEffects.ideal(), "hdl64")
    low = _scan(ground, SensorEffects.ideal(elevation_error_deg=-0.205), "hdl64")
    far = np.linalg.norm(flat[:, :2], axis=1) > 20.0
    # the stored elevation is lower than the ray's: the road looks lower far away
    assert np.median(low[np.linalg.norm(low[:, :2], axis=1) > 20.0, 2]) < np.median(
        flat[far, 2]) - 0.05
    jit = _range_error(room, SensorEffects.ideal(angle_jitter_deg=0.5))[1]
    assert 1e-3 < np.median(np.abs(jit)) < 0.2  # the ray went elsewhere: another range


def test_kitti_hdl64_geometry_and_its_car() -> None:
    """The HDL-64E is KITTI's unit: its own elevations and laser heights; with the ego vehicle
    the car's sectors never return."""
    sensor = get_sensor("hdl64")
    assert sensor.elevations_deg == kitti_sensor.ELEVATIONS_DEG
    assert len(set(np.round(np.diff(sensor.elevations_deg), 2))) > 10  # not evenly spaced
    assert sensor.laser_heights()[0] > 0.15 and sensor.azimuths == kitti_sensor.FIRINGS
    scene = _scene(_ground())
    free = _scan(scene, SensorEffects.ideal(), "hdl64")
    car = _scan(scene, SensorEffects.ideal(ego_vehicle=True), "hdl64")
    behind = lambda p: np.abs(np.degrees(np.arctan2(p[:, 1], p[:, 0]))) > 170  # noqa: E731
    low = lambda p: np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]))) < -20  # noqa: E731
    assert (behind(free) & low(free)).sum() > 100 and (behind(car) & low(car)).sum() == 0
    assert len(car) < len(free)


def test_foliage_returns_come_from_inside_the_crown() -> None:
    crown = meshes.rock(np.array([12.0, 0.0, 0.0]), 2.0, np.random.default_rng(1))
    scene = _scene((*crown, Material.VEGETATION))
    v, t, m = scene
    caster = Raycaster(v, t, get_sensor("hdl32"), m)
    solid = _scan(scene, SensorEffects.ideal(), "hdl32")
    volume = _scan(scene, SensorEffects.ideal(vegetation_free_path_m=1.0), "hdl32")
    d_solid = caster.distance_to_mesh(solid[:, :3].astype(np.float64))
    d_volume = caster.distance_to_mesh(volume[:, :3].astype(np.float64))
    assert np.quantile(d_solid, 0.99) < 0.01
    assert np.median(d_volume) > 0.2 and len(volume) <= len(solid)


def test_moving_vehicles_move_between_frames() -> None:
    xy = np.stack([np.arange(0.0, 400.0, 0.25), np.zeros(1600)], axis=1)
    route = Route(xy, np.zeros(1600), np.zeros(1600, np.int64), ("road",), np.full(1600, -1.73))
    traffic = Traffic(route, np.array([3.5]), np.array([30.0]), np.array([-10.0]))
    (c0,), _ = traffic.positions(0.0)
    (c1,), _ = traffic.positions(0.5)
    assert c1[0] == pytest.approx(c0[0] - 5.0, abs=0.3) and c0[1] == pytest.approx(3.5)
    scene = _scene(_ground())
    v, t, m = scene
    caster = Raycaster(v, t, get_sensor("hdl32", SensorEffects.ideal()), m)
    seen = []
    for when in (0.0, 0.5):
        pts = caster.scan(HOME, np.random.default_rng(0), traffic.mesh_at(when))
        on_car = pts[(pts[:, 2] > -1.0) & (np.abs(pts[:, 1] - 3.5) < 1.5)]
        seen.append(on_car[:, 0].min())
    assert seen[1] == pytest.approx(seen[0] - 5.0, abs=0.5)
    assert not (_scan(scene, SensorEffects.ideal(), "hdl32")[:, 2] > -1.0).any()
