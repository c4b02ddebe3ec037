"""The numba kernel of the descriptor's voxel moments (pipeline/descriptors/ndt_histogram.py).

Imported by ``pipeline.descriptors.ndt_histogram`` on first use. It gives what the numpy reference
``voxel_moments(_crop(points))`` gives (tests/test_descriptor.py compares them on real scans),
without the dozen (N,) temporaries whose page faults dominate the numpy path.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

Moments = tuple[bool, NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]
"""What the kernel returns: (ok, counts (M,), mean (M, 3), covariance (M, 3, 3))."""


@numba.njit(cache=True, nogil=True, inline="always")
def _cell(
    p: NDArray[np.float32], inv: np.float32, r2max: np.float32,
    lo0: int, lo1: int, lo2: int, d1: int, d2: int,
) -> int:  # pragma: no cover - compiled
    """Dense cell index of point p (>=3,) in the box starting at cell (lo0, lo1, lo2); -1 if
    p is farther than sqrt(r2max) or not finite."""
    x, y, z = p[0], p[1], p[2]
    if not x * x + y * y + z * z < r2max:
        return -1
    a, b, c = int(np.floor(x * inv)), int(np.floor(y * inv)), int(np.floor(z * inv))
    return ((a - lo0) * d1 + (b - lo1)) * d2 + (c - lo2)


@numba.njit(cache=True, nogil=True)
def voxel_moments_dense(
    pts: NDArray[np.float32], voxel_size_m: float, max_range_m: float, min_points: int,
    max_cells: int,
) -> Moments:  # pragma: no cover - compiled
    """``voxel_moments(_crop(pts))`` of pipeline.descriptors.ndt_histogram in three passes over
    the points.

    pts (N, >=3) float32 [m] in the sensor frame. Returns (ok, counts (M,), mean (M, 3) [m],
    covariance (M, 3, 3) [m^2]) of the voxels with >= min_points points, in cell order.

    Pass 1: the cell bounding box of the points within max_range_m (float32 arithmetic as the
    numpy path: the same cells); pass 2: points per cell; pass 3: float64 sums of the points of
    the cells with >= min_points. Returns (False, ...) when the box has more than max_cells.
    """
    inv = np.float32(1.0 / voxel_size_m)
    r2max = np.float32(max_range_m * max_range_m)
    big = 2**62
    lo0, lo1, lo2, hi0, hi1, hi2 = big, big, big, -big, -big, -big
    for i in range(pts.shape[0]):
        x, y, z = pts[i, 0], pts[i, 1], pts[i, 2]
        if x * x + y * y + z * z < r2max:  # NaN compares False: dropped
            a, b, c = np.floor(x * inv), np.floor(y * inv), np.floor(z * inv)
            lo0, lo1, lo2 = min(lo0, int(a)), min(lo1, int(b)), min(lo2, int(c))
            hi0, hi1, hi2 = max(hi0, int(a)), max(hi1, int(b)), max(hi2, int(c))
    d1, d2 = hi1 - lo1 + 1, hi2 - lo2 + 1
    n_cells = (hi0 - lo0 + 1) * d1 * d2 if hi0 >= lo0 else 0
    empty = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    if n_cells > max_cells:
        return False, empty[0], empty[1], empty[2]
    count = np.zeros(n_cells, np.int64)
    for i in range(pts.shape[0]):
        k = _cell(pts[i], inv, r2max, lo0, lo1, lo2, d1, d2)
        if k >= 0:
            count[k] += 1
    slot = np.full(n_cells, -1, np.int64)
    m = 0
    for k in range(n_cells):
        if count[k] >= min_points:
            slot[k] = m
            m += 1
    if m == 0:
        return True, empty[0], empty[1], empty[2]
    acc = np.zeros((m, 9))
    for i in range(pts.shape[0]):  # the cells again: cheaper than an (N,) array of them
        k = _cell(pts[i], inv, r2max, lo0, lo1, lo2, d1, d2)
        s = slot[k] if k >= 0 else -1
        if s >= 0:
            x, y, z = np.float64(pts[i, 0]), np.float64(pts[i, 1]), np.float64(pts[i, 2])
            acc[s, 0] += x
            acc[s, 1] += y
            acc[s, 2] += z
            acc[s, 3] += x * x
            acc[s, 4] += x * y
            acc[s, 5] += x * z
            acc[s, 6] += y * y
            acc[s, 7] += y * z
            acc[s, 8] += z * z
    counts = np.empty(m, np.int64)
    mean = np.empty((m, 3))
    cov = np.empty((m, 3, 3))
    for k in range(n_cells):
        s = slot[k]
        if s >= 0:
            counts[s] = count[k]
            f = 1.0 / count[k]
            mx, my, mz = acc[s, 0] * f, acc[s, 1] * f, acc[s, 2] * f
            mean[s, 0], mean[s, 1], mean[s, 2] = mx, my, mz
            cov[s, 0, 0] = acc[s, 3] * f - mx * mx
            cov[s, 0, 1] = cov[s, 1, 0] = acc[s, 4] * f - mx * my
            cov[s, 0, 2] = cov[s, 2, 0] = acc[s, 5] * f - mx * mz
            cov[s, 1, 1] = acc[s, 6] * f - my * my
            cov[s, 1, 2] = cov[s, 2, 1] = acc[s, 7] * f - my * mz
            cov[s, 2, 2] = acc[s, 8] * f - mz * mz
    return True, counts, mean, cov
