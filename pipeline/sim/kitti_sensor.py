"""KITTI's Velodyne HDL-64E S2 as its scans show it (docs/simulator.md, "Sensor model").

Estimated by ``studies.realism.sensor_fit.fit_sensor`` from the 40 scans of kitti_mini
(sequences 01, 04, 06, 10, frames 0-9; ``adaptune realism`` re-derives them): the elevation of
every laser as the files store it (ring 0 the highest), the height of every laser's origin above
the sensor's origin, and the azimuth sectors of the lowest rings that KITTI's car and roof rack
hide. The elevations are the unit's own calibration (the datasheet gives +2 .. -24.8 deg in two
blocks, 1/3 and 1/2 deg apart; this unit's spacings vary from 0.26 to 0.65 deg), and the upper
block sits 0.19-0.21 m above the origin, the lower one 0.12 m, as the HDL-64E's two laser blocks.
"""

from __future__ import annotations

ELEVATIONS_DEG = (
    1.933, 1.571, 1.301, 0.868, 0.576, 0.178, -0.090, -0.453, -0.805, -1.203,
    -1.495, -1.835, -2.208, -2.549, -2.875, -3.236, -3.537, -3.930, -4.208, -4.576,
    -4.897, -5.226, -5.585, -5.932, -6.299, -6.641, -6.961, -7.246, -7.633, -8.005,
    -8.253, -8.654, -8.966, -9.512, -10.000, -10.408, -10.894, -11.535, -12.051, -12.498,
    -12.976, -13.420, -13.983, -14.532, -15.124, -15.591, -16.111, -16.493, -17.135, -17.681,
    -18.277, -18.754, -19.277, -19.699, -20.182, -20.756, -21.283, -21.895, -22.405, -22.834,
    -23.298, -23.945, -24.461, -24.965,
)
"""Elevation of the 64 lasers [deg], as KITTI's files store it."""

HEIGHTS_M = (
    0.211, 0.211, 0.211, 0.210, 0.210, 0.209, 0.208, 0.207, 0.207, 0.206, 0.205, 0.205,
    0.204, 0.204, 0.203, 0.202, 0.200, 0.199, 0.198, 0.196, 0.194, 0.191, 0.191, 0.191,
    0.189, 0.188, 0.187, 0.187, 0.186, 0.185, 0.186, 0.184, 0.114, 0.114, 0.114, 0.114,
    0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114,
    0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114, 0.114,
    0.114, 0.114, 0.114, 0.114,
)
"""Height of each laser's origin above the sensor origin [m]."""

FIRINGS = 2170
"""Firings a laser makes in a revolution: the most returns a KITTI ring holds (KITTI's unit turned
at 9.64 Hz, times.txt, firing about 20.9 kHz a laser)."""

HIDDEN_SECTORS_DEG: dict[int, tuple[tuple[float, float], ...]] = {
    42: ((-160, -155), (160, 165)),
    43: ((-165, -155), (155, 165)),
    44: ((-160, -150), (160, 165)),
    45: ((-165, -155), (155, 165)),
    46: ((-160, -155), (160, 165)),
    47: ((-165, -155), (-75, -65), (155, 165)),
    48: ((-160, -155), (-75, -55), (160, 165)),
    49: ((-165, -160), (-80, -60), (160, 165)),
    50: ((-160, -155), (-75, -55), (160, 165)),
    51: ((-165, -160), (-80, -60), (160, 165)),
    52: ((-180, -165), (-160, -155), (-75, -55), (160, 165), (170, 180)),
    53: ((-180, -160), (-80, -60), (160, 180)),
    54: ((-180, -155), (-75, -55), (160, 180)),
    55: ((-180, -155), (-80, -60), (160, 180)),
    56: ((-180, -155), (-125, -120), (-75, -55), (135, 140), (160, 180)),
    57: ((-180, -155), (-130, -125), (-80, -60), (0, 10), (130, 135), (155, 180)),
    58: ((-180, -150), (-130, -120), (-75, -55), (-10, 15), (130, 140), (160, 180)),
    59: ((-180, -150), (-135, -125), (-80, -65), (-15, 15), (130, 135), (155, 180)),
    60: ((-180, -145), (-130, -120), (-75, -60), (-35, -25), (-15, 20), (130, 140), (155, 180)),
    61: ((-180, -150), (-130, -120), (-80, -70), (-40, -30), (-15, 20), (25, 30), (35, 40),
         (130, 145), (155, 180)),
    62: ((-180, -145), (-135, -120), (-75, -65), (-35, -25), (-20, 20), (30, 40), (130, 150),
         (155, 180)),
    63: ((-180, -120), (-80, -75), (-40, -30), (-20, 20), (25, 40), (130, 180)),
}
"""Ring -> azimuth sectors [deg] (from, to; x forward, counter-clockwise) the car hides: the rings
below -13 deg see the roof and the roof rack in front, behind and beside the sensor."""

ELEVATION_ERROR_DEG = -0.205
"""The error of KITTI's stored elevations (stored minus true): the scans need every point raised
by 0.205 deg about the axis perpendicular to its ray and z (Deschaud, "IMLS-SLAM", ICRA 2018;
KISS-ICP's and CT-ICP's KITTI loaders apply it)."""
