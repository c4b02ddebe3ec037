"""Spinning LiDAR sensor models: beam elevations, azimuth step, rate, range, noise, dropouts.

A scan is treated as instantaneous: every ray of frame k leaves the sensor at the pose of
frame k (no motion distortion within a scan; documented in pipeline/sim/__init__.py).
Ray directions are unit vectors in the lidar frame (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError


@dataclass(frozen=True)
class SensorModel:
    """A rotating multi-beam LiDAR.

    elevations_deg: (B,) beam elevations [deg], one per laser;
    azimuth_step_deg: horizontal resolution at ``rate_hz`` [deg];
    min_range_m / max_range_m: returns outside are dropped;
    range_noise_m: std of the Gaussian range noise [m];
    dropout: probability that a return is lost.
    """

    name: str
    elevations_deg: tuple[float, ...]
    azimuth_step_deg: float
    rate_hz: float = 10.0
    min_range_m: float = 0.5
    max_range_m: float = 100.0
    range_noise_m: float = 0.02
    dropout: float = 0.01

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

    def with_noise(
        self, range_noise_m: float | None = None, dropout: float | None = None
    ) -> SensorModel:
        """A copy with another range noise [m] and/or dropout probability."""
        out = self
        if range_noise_m is not None:
            if not 0.0 <= range_noise_m <= 1.0:
                raise ConfigError(f"range noise must be in [0, 1] m, got {range_noise_m}")
            out = replace(out, range_noise_m=float(range_noise_m))
        if dropout is not None:
            if not 0.0 <= dropout < 1.0:
                raise ConfigError(f"dropout must be in [0, 1), got {dropout}")
            out = replace(out, dropout=float(dropout))
        return out

    def ray_directions(self, azimuth_phase_deg: float = 0.0) -> NDArray[np.float32]:
        """(B * A, 3) float32 unit directions in the lidar frame, beam-major order."""
        el = np.deg2rad(np.asarray(self.elevations_deg, np.float64))[:, None]
        az = np.deg2rad(np.arange(self.azimuths) * self.azimuth_step_deg + azimuth_phase_deg)[
            None, :
        ]
        d = np.stack(
            [
                np.cos(el) * np.cos(az),
                np.cos(el) * np.sin(az),
                np.broadcast_to(np.sin(el), (el.shape[0], az.shape[1])),
            ],
            axis=-1,
        )
        return d.reshape(-1, 3).astype(np.float32)


def _hdl64_elevations() -> tuple[float, ...]:
    # Upper block: 32 lasers +2.0 .. -8.33 deg (1/3 deg); lower block: 32 lasers -8.83 .. -24.9 deg.
    upper = np.linspace(2.0, -8.33, 32)
    lower = np.linspace(-8.83, -24.9, 32)
    return tuple(float(x) for x in np.concatenate([upper, lower]))


SENSORS: dict[str, SensorModel] = {
    "hdl32": SensorModel(
        "hdl32",
        tuple(float(x) for x in np.linspace(-30.67, 10.67, 32)),
        azimuth_step_deg=0.2,
        max_range_m=100.0,
    ),
    "hdl64": SensorModel(
        "hdl64",
        _hdl64_elevations(),
        azimuth_step_deg=360.0 / 2083,
        max_range_m=120.0,
        min_range_m=2.5,
    ),
    "vlp16": SensorModel(
        "vlp16",
        tuple(float(x) for x in np.linspace(-15.0, 15.0, 16)),
        azimuth_step_deg=0.2,
        max_range_m=100.0,
    ),
}
"""HDL-32E (default), HDL-64E (KITTI's), VLP-16 at 10 Hz."""

SensorName = Literal["hdl32", "hdl64", "vlp16"]
"""A key of SENSORS, as the params sections type it (tests/sim/test_simulate_set.py: the same
names)."""

SENSOR_TITLES = {
    "hdl32": "Velodyne HDL-32E",
    "hdl64": "Velodyne HDL-64E",
    "vlp16": "Velodyne VLP-16",
}


def get_sensor(name: str) -> SensorModel:
    """The sensor model called ``name``; ConfigError listing the known names otherwise."""
    try:
        return SENSORS[name]
    except KeyError:
        raise ConfigError(f"unknown sensor {name!r} (known: {', '.join(SENSORS)})") from None
