"""KITTI's HDL-64E as its scans show it: per-laser elevations and heights, and the sectors the
car hides (docs/simulator.md, "Sensor model"). ``pipeline/sim/kitti_sensor.py`` holds the
values this estimate gave on the kitti_mini scans; ``adaptune realism`` can re-derive them.

Per ring (``ring_of_points``): the points obey z = h + rho tan(e) (rho the horizontal range),
e the laser's elevation and h the height of its origin above the sensor's. Upper block
(rings 0-31, which see far objects at every height): (h, e) by a robust line fit. Lower block
(rings 32-63, mostly ground at one distance, so h and e are not separable): h is the median
of rings 32-34's fits and e the median elevation seen from that height.
Occlusion: a ring's 5-degree azimuth sector is hidden by the car when fewer than half of the
expected returns came back in it over all scans, for rings whose beams point at the ground
near the car (elevation below -12 deg; above, a gap is sky or distance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from studies.realism.statistics import ring_of_points

SECTOR_DEG = 5.0


@dataclass(frozen=True)
class FittedSensor:
    """Per ring: elevation [deg] and origin height [m]; hidden sectors (ring, from, to) [deg]."""

    elevations_deg: tuple[float, ...]
    heights_m: tuple[float, ...]
    hidden: tuple[tuple[int, float, float], ...]


def fit_sensor(scans: list[NDArray[np.float32]], beams: int = 64,
               firings: int = 2170) -> FittedSensor:
    """The fit of the module docstring over ``scans`` ((N, >=3) float32, stored ring after
    ring) of a ``beams``-ring sensor with ``firings`` firings a ring and revolution."""
    z: list[list[NDArray[np.float64]]] = [[] for _ in range(beams)]
    rho: list[list[NDArray[np.float64]]] = [[] for _ in range(beams)]
    sectors = round(360.0 / SECTOR_DEG)
    counts = np.zeros((beams, sectors))
    for p in scans:
        ring = ring_of_points(p)
        az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
        np.add.at(counts, (ring, ((az + 180.0) // SECTOR_DEG).astype(int) % sectors), 1)
        r = np.hypot(p[:, 0], p[:, 1]).astype(np.float64)
        for k in range(beams):
            sel = ring == k
            z[k].append(p[sel, 2].astype(np.float64))
            rho[k].append(r[sel])
    half = beams // 2
    lines = [_line_fit(np.concatenate(z[k]), np.concatenate(rho[k])) if k < half + 3 else None
             for k in range(beams)]
    lower_h = float(np.median([lines[k][0] for k in range(half, half + 3)]))  # type: ignore[index]
    heights = [lines[k][0] if k < half else lower_h for k in range(beams)]  # type: ignore[index]
    elevations = [
        float(np.degrees(np.arctan(lines[k][1]))) if k < half  # type: ignore[index]
        else float(np.degrees(np.median(np.arctan2(np.concatenate(z[k]) - lower_h,
                                                   np.concatenate(rho[k])))))
        for k in range(beams)]
    expected = len(scans) * firings / sectors
    hidden = []
    for k in range(beams):
        if elevations[k] > -12.0:
            continue
        blocked = counts[k] < 0.5 * expected
        for a, b in _runs(blocked):
            hidden.append((k, -180.0 + a * SECTOR_DEG, -180.0 + b * SECTOR_DEG))
    return FittedSensor(tuple(round(e, 3) for e in elevations),
                        tuple(round(float(h), 3) for h in heights), tuple(hidden))


def _line_fit(z: NDArray[np.float64], rho: NDArray[np.float64]) -> tuple[float, float]:
    """(intercept, slope) of z = a + b rho, trimmed iteratively at 3 robust sigmas."""
    A = np.stack([np.ones_like(rho), rho], axis=1)
    keep = np.ones(len(z), bool)
    coef: NDArray[np.floating] = np.zeros(2)
    for _ in range(6):
        coef = np.linalg.lstsq(A[keep], z[keep], rcond=None)[0]
        res = z - A @ coef
        scale = 1.4826 * np.median(np.abs(res[keep])) + 1e-9
        keep = np.abs(res) < 3.0 * scale
    return float(coef[0]), float(coef[1])


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[start, end) index runs of True in ``mask``."""
    m = np.concatenate([[0], mask.astype(np.int8), [0]])
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))
