"""The compiled glue of the surfaces' relief (numba; ``pipeline.sim.raycast.Relief`` keeps its
plane waves' products and sines in numpy, where they vectorise): the hits on rough surfaces,
the sum of every hit's waves and the heights laid out per ray (docs/simulator.md, "Speed").

Why compiled: numpy spent 3-4 ms of an HDL-32E sweep on the gathers, scatters and row sums
around 1 ms of sines. The arithmetic is numpy's to the bit: float32 products and sums, a row of
waves summed pairwise as numpy's ``sum(axis=1)`` does.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@numba.njit(cache=True, nogil=True)
def rough_hits(rays: F32, t: F32, material: NDArray[np.uint8], relief: F32
               ) -> tuple[NDArray[np.int64], F32]:  # pragma: no cover - compiled
    """The rays that hit a rough surface (``t`` (M,) finite, ``relief[material]`` > 0): their
    indices (K,) and hit points (K, 3) origin + t direction (``rays`` (M, 6))."""
    rough = np.empty(len(t), np.int64)
    k = 0
    for j in range(len(t)):
        if math.isfinite(t[j]) and relief[material[j]] > 0.0:
            rough[k] = j
            k += 1
    hit = np.empty((k, 3), np.float32)
    for i in range(k):
        j = rough[i]
        for c in range(3):
            hit[i, c] = rays[j, c] + rays[j, 3 + c] * t[j]
    return rough[:k], hit


@numba.njit(cache=True, nogil=True)
def row_sums(a: F32) -> F32:  # pragma: no cover - compiled
    """(K,) the sums of the rows of ``a`` (K, W), W <= 128, in numpy's pairwise order (eight
    partial sums from 8 columns on, joined as a tree; fewer columns: one after the other)."""
    n, w = a.shape
    out = np.empty(n, np.float32)
    for i in range(n):
        if w < 8:
            s = np.float32(0.0)
            for c in range(w):
                s += a[i, c]
            out[i] = s
            continue
        r0, r1, r2, r3, r4, r5, r6, r7 = a[i, 0], a[i, 1], a[i, 2], a[i, 3], a[i, 4], \
            a[i, 5], a[i, 6], a[i, 7]
        c = 8
        while c + 8 <= w:
            r0, r1, r2, r3 = r0 + a[i, c], r1 + a[i, c + 1], r2 + a[i, c + 2], r3 + a[i, c + 3]
            r4, r5, r6, r7 = (r4 + a[i, c + 4], r5 + a[i, c + 5], r6 + a[i, c + 6],
                              r7 + a[i, c + 7])
            c += 8
        s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        for q in range(c, w):
            s += a[i, q]
        out[i] = s
    return out


@numba.njit(cache=True, nogil=True)
def lay_relief(height: F32, rough: NDArray[np.int64], bumps: F32, material: NDArray[np.uint8],
               relief: F32, relief_m: float) -> None:  # pragma: no cover - compiled
    """``height[rough[i]]`` = ``bumps[i]`` x (``relief_m`` x ``relief[material]``) [m]."""
    scale = np.float32(relief_m)
    for i in range(len(rough)):
        j = rough[i]
        height[j] = bumps[i] * (scale * relief[material[j]])
