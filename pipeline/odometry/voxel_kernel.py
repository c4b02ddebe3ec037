"""The compiled voxel grid of the ``ndt`` adapter's source clouds (numba): the packed voxel keys
of a cloud and the centroids of its occupied voxels, to the last bit what the numpy code of
``common.voxel_downsample`` gave before (``tests/odometry/test_voxel_kernel.py``).

Why compiled: every frame of an untuned run (evaluate, adaptive, the suites' replicas)
downsamples its scan, and in numpy that was 3 ms of a 4-5 ms NDT frame: six temporaries of the
cloud, a gather and ``np.add.reduceat``. The sort stays numpy's ``argsort`` (its order of equal
keys is numpy's own, and the sums depend on it). The sums are numpy's too: ``reduceat`` keeps a
voxel's first point and adds numpy's pairwise sum of the others (``_pairwise_sum``, numpy's
``pairwise_sum`` of its float64 add loop, blocks of 8 accumulators up to 128 terms, halves
above).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from pipeline.odometry.voxel_key import packed_voxel_key

_PAIRWISE_BLOCK = 128
"""numpy's PW_BLOCKSIZE: above it the pairwise sum splits in two."""


@numba.njit(cache=True, nogil=True)
def voxel_keys_of(points: NDArray[np.floating], inv_voxel: float
                  ) -> NDArray[np.int64]:  # pragma: no cover - compiled
    """(N,) int64 packed keys (``common.pack_keys``) of the voxels holding ``points`` (N, 3)
    [m], float32 or float64 (taken as float64), ``inv_voxel`` = 1 / voxel side [1/m]."""
    no_offset = np.zeros((1, 3), np.int64)
    keys = np.empty(points.shape[0], np.int64)
    for i in range(points.shape[0]):  # the voxel map's own key of a point (ndt_kernel)
        keys[i] = packed_voxel_key(np.float64(points[i, 0]), np.float64(points[i, 1]),
                             np.float64(points[i, 2]), inv_voxel, no_offset, 0)
    return keys


@numba.njit(cache=True, nogil=True)
def _pairwise_sum(points: NDArray[np.floating], order: NDArray[np.int64], start: int, n: int,
                  axis: int) -> float:  # pragma: no cover - compiled
    """numpy's pairwise sum of ``points[order[start:start + n], axis]`` (as float64)."""
    if n < 8:
        res = -0.0  # numpy's start: a sum of negative zeros stays -0.0
        for i in range(start, start + n):
            res += np.float64(points[order[i], axis])
        return res
    if n <= _PAIRWISE_BLOCK:
        r = np.empty(8)
        for j in range(8):
            r[j] = np.float64(points[order[start + j], axis])
        i = 8
        while i < n - n % 8:
            for j in range(8):
                r[j] += np.float64(points[order[start + i + j], axis])
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += np.float64(points[order[start + i], axis])
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return (_pairwise_sum(points, order, start, n2, axis)
            + _pairwise_sum(points, order, start + n2, n - n2, axis))


@numba.njit(cache=True, nogil=True)
def sorted_centroids(points: NDArray[np.floating], keys: NDArray[np.int64],
                     order: NDArray[np.int64]) -> NDArray[np.float64]:  # pragma: no cover
    """(M, 3) float64 centroids of the occupied voxels of ``points`` (N, 3) [m] in the order of
    their ``keys`` (N,); ``order`` (N,): ``np.argsort(keys)``. A voxel's sum is its first point
    (in ``order``) plus the pairwise sum of the others, as ``np.add.reduceat`` adds."""
    n = len(order)
    starts = np.empty(n + 1, np.int64)
    m = 0
    for j in range(n):
        if j == 0 or keys[order[j]] != keys[order[j - 1]]:
            starts[m] = j
            m += 1
    starts[m] = n
    out = np.empty((m, 3))
    for g in range(m):
        first, count = starts[g], starts[g + 1] - starts[g]
        for axis in range(3):
            total = np.float64(points[order[first], axis])
            if count > 1:
                total += _pairwise_sum(points, order, first + 1, count - 1, axis)
            out[g, axis] = total / count
    return out
