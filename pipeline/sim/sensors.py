"""Spinning LiDAR sensor models: beam elevations, laser origins, firings a revolution, rate,
range limits and the physical effects (``pipeline.sim.effects.SensorEffects``).

Ray directions are unit vectors in the lidar frame (x forward, y left, z up), beam-major: ray
b * A + a is laser b's firing a of a revolution, a = 0 facing forward and a growing
counter-clockwise (docs/simulator.md, "Sensor model").
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.sim import kitti_sensor
from pipeline.sim.effects import SensorEffects


@dataclass(frozen=True)
class SensorModel:
    """A rotating multi-beam LiDAR.

    elevations_deg: (B,) beam elevations [deg], one per laser, as the sensor reports them;
    heights_m: (B,) height of each laser's origin above the sensor origin [m] (() = all 0);
    azimuth_step_deg: horizontal resolution [deg]; rate_hz: revolutions a second;
    min_range_m / max_range_m: returns outside are dropped; effects: the physical effects;
    hidden_deg: ring -> azimuth sectors [deg] the carrier hides (with ``effects.ego_vehicle``).
    """

    name: str
    elevations_deg: tuple[float, ...]
    azimuth_step_deg: float
    rate_hz: float = 10.0
    min_range_m: float = 0.5
    max_range_m: float = 100.0
    heights_m: tuple[float, ...] = ()
    effects: SensorEffects = field(default_factory=lambda: SensorEffects.model_validate({}))
    hidden_deg: dict[int, tuple[tuple[float, float], ...]] = field(default_factory=dict)

    @property
    def beams(self) -> int:
        return len(self.elevations_deg)

    @property
    def azimuths(self) -> int:
        """Number of firings per revolution."""
        return round(360.0 / self.azimuth_step_deg)

    @property
    def vertical_fov_deg(self) -> tuple[float, float]:
        """(lowest, highest) beam elevation [deg]."""
        return min(self.elevations_deg), max(self.elevations_deg)

    @property
    def range_noise_m(self) -> float:
        return self.effects.range_noise_m

    @property
    def dropout(self) -> float:
        return self.effects.dropout

    def with_effects(self, effects: SensorEffects) -> SensorModel:
        """A copy with other physical effects."""
        return replace(self, effects=effects)

    def with_noise(
        self, range_noise_m: float | None = None, dropout: float | None = None
    ) -> SensorModel:
        """A copy with another range noise [m] and/or dropout probability."""
        update: dict[str, float] = {}
        if range_noise_m is not None:
            if not 0.0 <= range_noise_m <= 0.5:
                raise ConfigError(f"range noise must be in [0, 0.5] m, got {range_noise_m}")
            update["range_noise_m"] = float(range_noise_m)
        if dropout is not None:
            if not 0.0 <= dropout < 1.0:
                raise ConfigError(f"dropout must be in [0, 1), got {dropout}")
            update["dropout"] = float(dropout)
        return self.with_effects(self.effects.model_copy(update=update))

    def laser_heights(self) -> NDArray[np.float64]:
        """(B,) height of every laser's origin [m]."""
        return np.asarray(self.heights_m or (0.0,) * self.beams, np.float64)

    def ray_directions(self, azimuth_phase_deg: float = 0.0,
                       elevations_deg: NDArray[np.float64] | None = None,
                       azimuth_offsets_deg: NDArray[np.float64] | None = None
                       ) -> NDArray[np.float32]:
        """(B * A, 3) float32 unit directions in the lidar frame, beam-major order; by default
        at the reported elevations, else at ``elevations_deg`` (B,), each laser's azimuths
        shifted by ``azimuth_offsets_deg`` (B,)."""
        el_deg = np.asarray(self.elevations_deg if elevations_deg is None else elevations_deg,
                            np.float64)
        el = np.deg2rad(el_deg)[:, None]
        off = np.zeros(self.beams) if azimuth_offsets_deg is None else azimuth_offsets_deg
        az = np.deg2rad(np.arange(self.azimuths)[None, :] * self.azimuth_step_deg
                        + azimuth_phase_deg + np.asarray(off, np.float64)[:, None])
        d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                      np.broadcast_to(np.sin(el), az.shape)], axis=-1)
        return d.reshape(-1, 3).astype(np.float32)

    def hidden_rays(self) -> NDArray[np.bool_]:
        """(B * A,) True where the carrier hides the ray (``effects.ego_vehicle``)."""
        out = np.zeros((self.beams, self.azimuths), bool)
        if self.effects.ego_vehicle:
            az = (np.arange(self.azimuths) * self.azimuth_step_deg + 180.0) % 360.0 - 180.0
            for ring, sectors in self.hidden_deg.items():
                for a, b in sectors:
                    out[ring] |= (az >= a) & (az < b)
        return out.reshape(-1)


SENSORS: dict[str, SensorModel] = {
    "hdl32": SensorModel(
        "hdl32",
        tuple(float(x) for x in np.linspace(-30.67, 10.67, 32)),
        azimuth_step_deg=0.2,
        max_range_m=100.0,
    ),
    "hdl64": SensorModel(
        "hdl64",
        kitti_sensor.ELEVATIONS_DEG,
        azimuth_step_deg=360.0 / kitti_sensor.FIRINGS,
        max_range_m=120.0,
        min_range_m=2.5,
        heights_m=kitti_sensor.HEIGHTS_M,
        hidden_deg=kitti_sensor.HIDDEN_SECTORS_DEG,
    ),
    "vlp16": SensorModel(
        "vlp16",
        tuple(float(x) for x in np.linspace(-15.0, 15.0, 16)),
        azimuth_step_deg=0.2,
        max_range_m=100.0,
    ),
}
"""HDL-32E (default; datasheet elevations -30.67 .. +10.67 deg, 1.33 deg apart), HDL-64E
(KITTI's unit: pipeline/sim/kitti_sensor.py), VLP-16 (+-15 deg, 2 deg apart) at 10 Hz."""

SensorName = Literal["hdl32", "hdl64", "vlp16"]
"""A key of SENSORS, as the params sections type it (tests/sim/test_simulate_set.py: the same
names)."""

SENSOR_TITLES = {
    "hdl32": "Velodyne HDL-32E",
    "hdl64": "Velodyne HDL-64E",
    "vlp16": "Velodyne VLP-16",
}


def get_sensor(name: str, effects: SensorEffects | None = None) -> SensorModel:
    """The sensor model called ``name`` (with ``effects`` where given); ConfigError listing
    the known names otherwise."""
    try:
        sensor = SENSORS[name]
    except KeyError:
        raise ConfigError(f"unknown sensor {name!r} (known: {', '.join(SENSORS)})") from None
    return sensor if effects is None else sensor.with_effects(effects)
