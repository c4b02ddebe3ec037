"""The simulator's compiled kernels give what the numpy / numba code before them gave
(docs/simulator.md, "Speed"): numba's random stream to the bit, the returns of a scan the
same however many threads shape them, the rays and relief sums as numpy computes them."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from pipeline.sim.mt19937 import fill, seeded
from pipeline.sim.rays_kernel import turn_rays
from pipeline.sim.relief_kernel import row_sums
from pipeline.sim.returns_kernel import GROUND, draw_uniforms, shape_returns
from pipeline.sim.returns_kernel import _normal as _polar_normal


@numba.njit
def _numba_doubles(seed: int, n: int) -> np.ndarray:
    np.random.seed(seed)
    out = np.empty(n)
    for i in range(n):
        out[i] = np.random.random()
    return out


@numba.njit
def _numba_draws(seed: int, t: np.ndarray, mat: np.ndarray, cover: float,
                 free_path: float) -> np.ndarray:
    """The random numbers the per-return kernel took from numba's np.random before it was
    split (depth, blade, detection normal, dropout, noise normal per ray with a return)."""
    np.random.seed(seed)
    out = np.full((len(t), 5), np.nan)
    for j in range(len(t)):
        if not math.isfinite(t[j]):
            continue
        if cover > 0.0 and mat[j] == GROUND:
            out[j, 0] = np.random.exponential(free_path)
            out[j, 1] = np.random.random()
        out[j, 2] = np.random.standard_normal()
        out[j, 3] = np.random.random()
        out[j, 4] = np.random.standard_normal()
    return out


# The transforms as the kernel applies them, compiled as it is: numpy's own log and sqrt may
# differ from numba's in the last bit on a CPU where numpy dispatches them to AVX-512 code
# (docs/results/seed-spread.md, "Another machine").
@numba.njit
def _exponential(u: np.ndarray, scale: float) -> np.ndarray:
    """shape_returns' blade depth, -ln(1 - u) * scale, of every u."""
    out = np.empty(len(u))
    for i in range(len(u)):
        out[i] = -math.log(1.0 - u[i]) * scale
    return out


@numba.njit
def _normals(r2: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The kernel's own polar-method normal of every pair (r2, x)."""
    out = np.empty(len(r2))
    for i in range(len(r2)):
        out[i] = _polar_normal(r2[i], x[i])
    return out


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**31 - 1])
def test_stream_is_numbas_np_random(seed: int) -> None:
    mt, buf, pos = seeded(seed)
    out = np.empty(2000)  # several refills of the 312-double block
    fill(mt, buf, pos, out[:7])
    fill(mt, buf, pos, out[7:])
    assert np.array_equal(out, _numba_doubles(seed, 2000))


def test_drawn_uniforms_give_numbas_numbers() -> None:
    """draw_uniforms + the transforms shape_returns applies = numba's exponential, random and
    standard_normal in the old order, with misses and ground rays mixed."""
    rng = np.random.default_rng(3)
    n = 20000  # several top-ups of the kernel's 4096-number window
    t = rng.uniform(1.0, 50.0, n).astype(np.float32)
    t[rng.random(n) < 0.2] = np.inf
    mat = rng.integers(0, 4, n).astype(np.uint8)
    u = draw_uniforms(77, t, mat, 0.15)
    want = _numba_draws(77, t, mat, 0.15, 1.0)
    ok = np.isfinite(t)
    ground = ok & (mat == GROUND)
    assert np.array_equal(_exponential(u[ground, 0], 1.0), want[ground, 0])
    assert np.array_equal(u[ground, 1], want[ground, 1])
    assert np.array_equal(_normals(u[ok, 2], u[ok, 3]), want[ok, 2])
    assert np.array_equal(u[ok, 4], want[ok, 3])
    assert np.array_equal(_normals(u[ok, 5], u[ok, 6]), want[ok, 4])


def test_returns_do_not_depend_on_the_split() -> None:
    rng = np.random.default_rng(5)
    n = 9000
    t = rng.uniform(1.0, 80.0, n).astype(np.float32)
    t[rng.random(n) < 0.3] = np.inf
    mat = rng.integers(0, 4, n).astype(np.uint8)
    unit = lambda k: (v := rng.standard_normal((k, 3)).astype(np.float32)) / np.linalg.norm(  # noqa: E731
        v, axis=1, keepdims=True)
    args = (draw_uniforms(9, t, mat, 0.15), t, unit(n), mat, np.full(n, -1.0, np.float32),
            rng.normal(0, 0.05, n).astype(np.float32), unit(n), np.zeros(n, np.float32),
            unit(n), np.zeros((n, 3), np.float32), np.array([0.1, 0.5, 0.9, 0.7], np.float32),
            np.array([0.15, 1.0, math.log(75.0**2 / 0.1), 0.3, 0.5, 0.01, 1e-4, 1e-4, 4e-4,
                      0.5, 100.0]))
    results = []
    for parts in (1, 2, 3):
        points, kept = np.zeros((n, 4), np.float32), np.zeros(n, bool)
        for part in range(parts):
            shape_returns(part, parts, *args, points, kept)
        results.append((points[kept], np.flatnonzero(kept)))
    assert 0 < len(results[0][1]) < n
    for points, rows in results[1:]:
        assert np.array_equal(points, results[0][0]) and np.array_equal(rows, results[0][1])


def test_turned_rays_are_the_rotated_directions() -> None:
    rng = np.random.default_rng(2)
    free = rng.standard_normal((500, 3)).astype(np.float32)
    column = rng.integers(0, 7, 500)
    R = np.linalg.qr(rng.standard_normal((7, 3, 3)))[0].astype(np.float32)
    t = rng.standard_normal((7, 3)).astype(np.float32)
    height = rng.uniform(0.0, 0.2, 500).astype(np.float32)
    rays = np.empty((500, 6), np.float32)
    turn_rays(free, column, R, t, height, True, np.zeros((0, 3), np.float32), 0.0, rays)
    want_dirs = np.einsum("nij,nj->ni", R[column].astype(np.float64), free)
    want_orig = t[column] + height[:, None] * R[column, :, 2]
    np.testing.assert_allclose(rays[:, 3:], want_dirs, rtol=0, atol=2e-6)
    assert np.array_equal(rays[:, :3], want_orig)


@pytest.mark.parametrize("waves", [3, 8, 13, 24])
def test_row_sums_are_numpys(waves: int) -> None:
    a = np.sin(np.random.default_rng(waves).standard_normal((3000, waves)) * 9).astype(np.float32)
    assert np.array_equal(row_sums(a), a.sum(axis=1))


def test_a_scan_is_the_same_on_one_thread_or_more() -> None:
    from pipeline.sim.raycast import Raycaster
    from pipeline.sim.simulate import SimSpec, make_world, scan_frame

    spec = SimSpec("street", 4, 3, "vlp16", motion="compensated")
    world = make_world(spec)
    scans = [scan_frame(Raycaster(world.vertices, world.triangles, spec.sensor_model(),
                                  world.materials, world.seed, threads=n), world, 4, 1,
                        spec.motion).points_lidar for n in (1, 2, 3)]
    assert len(scans[0]) > 1000
    assert all(np.array_equal(s, scans[0]) for s in scans[1:])
