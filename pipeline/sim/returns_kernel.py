"""The compiled per-return part of the sensor model (numba): for every ray of a scan, its
incidence, the surface relief along it, grass on soil, whether the echo comes back, range noise
and the laser's offset, and the point as the sensor reports it (docs/simulator.md, "Sensor
effects"; the models are ``SensorEffects``'s). The relief's height field is evaluated
beforehand (``pipeline.sim.raycast.Relief``).

Why compiled: a scan has 50-140 thousand rays and a dozen per-ray steps; in numpy most of the
simulator's time beside the ray casting went to the arrays those steps allocate. Two kernels
(docs/simulator.md, "Speed"): ``draw_uniforms`` runs through the rays in order and takes the
random numbers of each from numba's generator stream seeded per scan from the scan's numpy
generator (``pipeline.sim.mt19937``), so a scan stays reproducible from its seed;
``shape_returns`` does the rest, every ray on its own, in parts that threads share. The points
are what one loop over numba's ``np.random`` gave, to the bit (tests/sim/test_sim_kernels.py).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from pipeline.sim.mt19937 import fill, seeded

F32 = NDArray[np.float32]

GROUND = 0
"""``Material.GROUND``: soil and grass (the material the grass layer covers)."""


BLOCK = 2048
"""Rays a thread takes at a time (``shape_returns``)."""
DRAWS = 7
"""Random numbers a ray may take, in the order it takes them (``draw_uniforms``)."""


@numba.njit(cache=True, nogil=True)
def draw_uniforms(seed: int, t: F32, mat: NDArray[np.uint8], cover: float
                  ) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """(M, DRAWS) the uniform numbers behind every random number ray j takes, from numba's
    generator seeded with ``seed``, in the order the rays take them: the rays with a return
    (``t[j]`` finite) one after the other, each the grass layer's depth and blade (ground
    ``mat[j]`` under ``cover`` > 0 only), a standard normal (detection), the dropout's
    uniform, a standard normal (range noise). Row j: u_depth, u_blade, r2 and x of the
    detection's normal, u_dropout, r2 and x of the noise's normal; ``shape_returns`` turns
    them into the numbers numba's ``np.random.exponential``, ``random`` and
    ``standard_normal`` would have given (Marsaglia's polar method: a pair (x1, x2) gives the
    normals f x2 and then f x1, f = sqrt(-2 ln(r2) / r2)).

    The one sequential part of a scan's returns: the generator's stream, not the arithmetic.
    """
    mt, buf, pos = seeded(seed)
    d = np.empty(4096)  # the next numbers of the stream, read from p on
    fill(mt, buf, pos, d)
    p = 0
    u = np.empty((len(t), DRAWS))
    waiting, r2_waiting, x_waiting = False, 0.0, 0.0  # the polar pair's second normal
    for j in range(len(t)):
        if not math.isfinite(t[j]):
            continue
        if cover > 0.0 and mat[j] == GROUND:
            if p > len(d) - 2:
                p = _top_up(d, p, mt, buf, pos)
            u[j, 0], u[j, 1] = d[p], d[p + 1]
            p += 2
        for col in (2, 5):  # the two normals, the dropout's uniform between them
            if col == 5:
                if p > len(d) - 1:
                    p = _top_up(d, p, mt, buf, pos)
                u[j, 4] = d[p]
                p += 1
            if waiting:
                u[j, col], u[j, col + 1] = r2_waiting, x_waiting
                waiting = False
                continue
            while True:
                if p > len(d) - 2:
                    p = _top_up(d, p, mt, buf, pos)
                x1 = 2.0 * d[p] - 1.0
                x2 = 2.0 * d[p + 1] - 1.0
                p += 2
                r2 = x1 * x1 + x2 * x2
                if r2 < 1.0 and r2 != 0.0:
                    break
            u[j, col], u[j, col + 1] = r2, x2
            waiting, r2_waiting, x_waiting = True, r2, x1
    return u


@numba.njit(cache=True, nogil=True)
def _top_up(d: NDArray[np.float64], p: int, mt: NDArray[np.uint32], buf: NDArray[np.float64],
            pos: NDArray[np.int64]) -> int:  # pragma: no cover - compiled
    """0, after moving the numbers of ``d`` not read yet (from ``p``) to its front and filling
    the stream's next numbers behind them."""
    rest = len(d) - p
    d[:rest] = d[p:]
    fill(mt, buf, pos, d[rest:])
    return 0


@numba.njit(cache=True, nogil=True)
def _normal(r2: float, x: float) -> float:  # pragma: no cover - compiled
    """The standard normal of the polar method's pair with squared radius r2 and coordinate x."""
    return math.sqrt(-2.0 * math.log(r2) / r2) * x


@numba.njit(cache=True, nogil=True)
def shape_returns(part: int, parts: int, u: NDArray[np.float64], t: F32, normal: F32,
                  mat: NDArray[np.uint8], cos_set: F32, height: F32, dirs_w: F32, bias: F32,
                  out_dirs: F32, out_orig: F32, reflect: F32, settings: NDArray[np.float64],
                  points: F32, kept: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    """The returns of the rays of blocks ``part``, ``part + parts``, ... (BLOCK rays each):
    ``kept[j]``, and where kept the point ``points[j]`` (x, y, z, intensity). Rays are
    independent given their uniforms ``u`` (``draw_uniforms``): any split gives the same
    points, and ``parts`` threads share the work evenly (the blocks interleave the sensor's
    rings, which have returns on the ground and none in the sky).

    Per ray j: range ``t[j]`` (inf: no hit), the surface's ``normal[j]`` and material
    ``mat[j]`` (its incidence with the ray's direction ``dirs_w[j]``, unless ``cos_set[j]`` >= 0
    sets it: foliage), the height of the surface's relief there along its normal
    ``height[j]``, the laser's range offset ``bias[j]``, and where the sensor puts a return:
    ``out_orig[j]`` + r ``out_dirs[j]``. reflect: per material. settings: ground_cover_m,
    free_path_m, detection log constant (ln(range^2 / 0.1); nan: every echo returns),
    incidence exponent, detection spread, dropout, sigma0^2, growth / 100, divergence /
    sqrt(12), min and max range.
    """
    n = len(t)
    for start in range(part * BLOCK, n, parts * BLOCK):
        _shape_block(start, min(start + BLOCK, n), u, t, normal, mat, cos_set, height, dirs_w,
                     bias, out_dirs, out_orig, reflect, settings, points, kept)


@numba.njit(cache=True, nogil=True)
def _shape_block(first: int, last: int, u: NDArray[np.float64], t: F32, normal: F32,
                 mat: NDArray[np.uint8], cos_set: F32, height: F32, dirs_w: F32, bias: F32,
                 out_dirs: F32, out_orig: F32, reflect: F32, settings: NDArray[np.float64],
                 points: F32, kept: NDArray[np.bool_]) -> None:  # pragma: no cover - compiled
    """``shape_returns`` of the rays ``first`` .. ``last`` - 1."""
    cover, free_path, log_c, exponent, spread = settings[:5]
    dropout, var0, growth, spread_fp, r_min, r_max = settings[5:11]
    for j in range(first, last):
        kept[j] = False
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
            depth = -math.log(1.0 - u[j, 0]) * free_path
            if depth < path:
                ti -= path - depth
                ci = u[j, 1]
        back = True
        z_detect = _normal(u[j, 2], u[j, 3])
        if not math.isnan(log_c):  # echo power against the detection threshold
            power = (math.log(reflect[m]) + log_c + exponent * math.log(max(ci, 1e-6))
                     - 2.0 * math.log(max(ti, 0.1)))
            back = z_detect * spread < power
        back = u[j, 4] >= dropout and back
        var = var0 + (growth * ti) ** 2
        if spread_fp > 0.0:
            c = min(max(ci, 0.05), 1.0)
            var += (ti * math.sqrt(1.0 - c * c) / c * spread_fp) ** 2
        ri = ti + _normal(u[j, 5], u[j, 6]) * math.sqrt(var) + bias[j]
        if back and r_min <= ri <= r_max:
            points[j, 0] = out_orig[j, 0] + out_dirs[j, 0] * ri
            points[j, 1] = out_orig[j, 1] + out_dirs[j, 1] * ri
            points[j, 2] = out_orig[j, 2] + out_dirs[j, 2] * ri
            points[j, 3] = min(max(reflect[m] * ci, 0.0), 1.0)
            kept[j] = True


@numba.njit(cache=True, nogil=True)
def kept_rows(points: F32, kept: NDArray[np.bool_]
              ) -> tuple[F32, NDArray[np.int64]]:  # pragma: no cover - compiled
    """The rows of ``points`` (M, 4) where ``kept`` (M,), and their indices."""
    rows = np.flatnonzero(kept)
    out = np.empty((len(rows), 4), np.float32)
    for i in range(len(rows)):
        for c in range(4):
            out[i, c] = points[rows[i], c]
    return out, rows
