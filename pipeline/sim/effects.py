"""What a real spinning LiDAR does that an ideal ray caster does not: the switchable effects
of the sensor model (docs/simulator.md, "Sensor effects", gives each one's physics and
reference). ``SensorEffects`` is the nested ``effects`` mapping of the params sections
``simulate`` and ``simulate_kitti``; every effect is off at 0 (or false). The defaults are the
values calibrated against real KITTI (docs/simulator.md, "Calibration against real KITTI");
``KITTI_EFFECTS`` adds what is KITTI's recording's own: its car and its elevation error.
"""

from __future__ import annotations

from pydantic import Field

from pipeline.config import Section


class SensorEffects(Section):
    """The sensor model's physical effects.

    Range noise: Gaussian with sigma^2 = range_noise_m^2 + (range_noise_growth_m r / 100 m)^2
    + (r tan(incidence) beam_divergence_mrad 1e-3 / sqrt(12))^2: a floor, a growth with range
    (weaker echo) and the spread of ranges over the beam's footprint on an inclined surface.
    Calibration of the unit, fixed for a recording (drawn from ``unit_seed``): every laser's
    range offset (sigma ``laser_range_bias_m``), elevation error (sigma
    ``laser_elevation_error_deg``) and azimuth error (sigma ``laser_azimuth_error_deg``), plus
    ``elevation_error_deg`` common to all lasers (stored minus true elevation).
    ``angle_jitter_deg``: sigma of every firing's direction (azimuth and elevation), which the
    stored point does not know.
    Returns: an echo of power ~ reflectance cos(incidence)^incidence_exponent / r^2 comes back
    with probability Phi(ln(power / threshold) / detection_spread), the threshold being the
    power of a 10 % reflective target facing the beam at ``detection_range_m`` (0 = every echo
    comes back); then ``dropout`` of the returns is lost at random.
    ``vegetation_free_path_m``: mean free path of the beam inside foliage (returns from inside
    the crown, Beer-Lambert); 0 = crowns are solid surfaces. ``ground_cover_m``: height of the
    grass on ground (soil) surfaces, a layer of foliage the beam enters the same way (needs
    a free path > 0). ``surface_relief_m``: sigma of the relief (0.3-2 m wavelengths, fixed in
    the world) of facades, cars, soil and rock that the meshes leave out, scaled by material
    (``pipeline.sim.materials.RELIEF``).
    ``ego_vehicle``: the sensor's own car hides sectors of the lowest rings (KITTI's car;
    pipeline/sim/kitti_sensor.py); HDL-64E only.
    """

    range_noise_m: float = Field(0.01, ge=0.0, le=0.5)
    range_noise_growth_m: float = Field(0.01, ge=0.0, le=0.5)
    beam_divergence_mrad: float = Field(1.5, ge=0.0, le=20.0)
    laser_range_bias_m: float = Field(0.008, ge=0.0, le=0.5)
    laser_elevation_error_deg: float = Field(0.03, ge=0.0, le=1.0)
    laser_azimuth_error_deg: float = Field(0.05, ge=0.0, le=1.0)
    elevation_error_deg: float = Field(0.0, ge=-2.0, le=2.0)
    angle_jitter_deg: float = Field(0.01, ge=0.0, le=1.0)
    detection_range_m: float = Field(75.0, ge=0.0, le=1000.0)
    incidence_exponent: float = Field(0.3, ge=0.0, le=2.0)
    detection_spread: float = Field(0.5, gt=0.0, le=5.0)
    dropout: float = Field(0.01, ge=0.0, lt=1.0)
    vegetation_free_path_m: float = Field(1.0, ge=0.0, le=20.0)
    ground_cover_m: float = Field(0.15, ge=0.0, le=2.0)
    surface_relief_m: float = Field(0.08, ge=0.0, le=1.0)
    ego_vehicle: bool = False
    unit_seed: int = Field(0, ge=0)

    @classmethod
    def ideal(cls, **overrides: float | bool) -> SensorEffects:
        """Every effect off (an ideal ray caster), but ``overrides``."""
        off = {name: 0.0 for name in ("range_noise_m", "range_noise_growth_m",
                                      "beam_divergence_mrad", "laser_range_bias_m",
                                      "laser_elevation_error_deg", "laser_azimuth_error_deg",
                                      "elevation_error_deg",
                                      "angle_jitter_deg", "detection_range_m", "dropout",
                                      "vegetation_free_path_m", "ground_cover_m",
                                      "surface_relief_m")}
        return cls.model_validate(off | {"ego_vehicle": False} | overrides)


KITTI_EFFECTS = {"ego_vehicle": True, "elevation_error_deg": -0.205}
"""The effects of KITTI's recording on top of the defaults (simulated KITTI's defaults):
its car hides the lowest rings' sectors, its stored elevations are 0.205 deg low
(pipeline/sim/kitti_sensor.py)."""
