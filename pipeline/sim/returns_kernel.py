"""The compiled per-return part of the sensor model (numba): for every ray of a scan in one
loop, its incidence, the surface relief along it, grass on soil, whether the echo comes back,
range noise and the laser's offset, and the point as the sensor reports it (docs/simulator.md,
"Sensor effects"; the models are ``SensorEffects``'s). The relief's height field is evaluated
beforehand in numpy (``pipeline.sim.raycast.Relief``), where its sines vectorise.

Why compiled: a scan has 50-140 thousand rays and a dozen per-ray steps; in numpy most of the
simulator's time beside the ray casting went to the arrays those steps allocate. The random
numbers come from numba's generator seeded per scan from the scan's numpy generator, so a scan
stays reproducible from its seed.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

GROUND = 0
"""``Material.GROUND``: soil and grass (the material the grass layer covers)."""


@numba.njit(cache=True, nogil=True)
def shape_returns(seed: int, t: F32, normal: F32, mat: NDArray[np.uint8], cos_set: F32,
                  height: F32, dirs_w: F32, bias: F32, out_dirs: F32, out_orig: F32,
                  reflect: F32, settings: NDArray[np.float64]
                  ) -> tuple[F32, NDArray[np.int64]]:  # pragma: no cover - compiled
    """The kept points of M rays: ((K, 4) x, y, z, intensity; (K,) index of each one's ray).

    Per ray j: range ``t[j]`` (inf: no hit), the surface's ``normal[j]`` and material
    ``mat[j]`` (its incidence with the ray's direction ``dirs_w[j]``, unless ``cos_set[j]`` >= 0
    sets it: foliage), the height of the surface's relief there along its normal
    ``height[j]``, the laser's range offset ``bias[j]``, and where the sensor puts a return:
    ``out_orig[j]`` + r ``out_dirs[j]``. reflect: per material. settings: ground_cover_m,
    free_path_m, detection log constant (ln(range^2 / 0.1); nan: every echo returns),
    incidence exponent, detection spread, dropout, sigma0^2, growth / 100, divergence /
    sqrt(12), min and max range.
    """
    cover, free_path, log_c, exponent, spread = settings[:5]
    dropout, var0, growth, spread_fp, r_min, r_max = settings[5:11]
    np.random.seed(seed)
    n = len(t)
    points = np.empty((n, 4), np.float32)
    rays = np.empty(n, np.int64)
    k = 0
    for j in range(n):
        ti = t[j]
        if not math.isfinite(ti):
            continue
        m = mat[j]
        if cos_set[j] >= 0.0:
            ci = cos_set[j]
        else:
            ci = abs(normal[j, 0] * dirs_w[j, 0] + normal[j, 1] * dirs_w[j, 1]
                     + normal[j, 2] * dirs_w[j, 2])
        ti += height[j] / max(ci, 0.2)  # the surface's relief, seen along the ray
        if cover > 0.0 and m == GROUND:  # a blade of the grass layer answers first
            path = cover / max(ci, 0.05)
            depth = np.random.exponential(free_path)
            blade = np.random.random()
            if depth < path:
                ti -= path - depth
                ci = blade
        back = True
        z_detect = np.random.standard_normal()
        if not math.isnan(log_c):  # echo power against the detection threshold
            power = (math.log(reflect[m]) + log_c + exponent * math.log(max(ci, 1e-6))
                     - 2.0 * math.log(max(ti, 0.1)))
            back = z_detect * spread < power
        back = np.random.random() >= dropout and back
        var = var0 + (growth * ti) ** 2
        if spread_fp > 0.0:
            c = min(max(ci, 0.05), 1.0)
            var += (ti * math.sqrt(1.0 - c * c) / c * spread_fp) ** 2
        ri = ti + np.random.standard_normal() * math.sqrt(var) + bias[j]
        if back and r_min <= ri <= r_max:
            points[k, 0] = out_orig[j, 0] + out_dirs[j, 0] * ri
            points[k, 1] = out_orig[j, 1] + out_dirs[j, 1] * ri
            points[k, 2] = out_orig[j, 2] + out_dirs[j, 2] * ri
            points[k, 3] = min(max(reflect[m] * ci, 0.0), 1.0)
            rays[k] = j
            k += 1
    return points[:k], rays[:k]
