"""The compiled ray builder of the ray caster (numba): every free ray of a scan turned from the
lidar frame into the world by its azimuth column's pose, with its laser's origin and the
firing's angle jitter, written straight into the (M, 6) buffer open3d casts
(``pipeline.sim.raycast``; docs/simulator.md, "Speed").

Why compiled: numpy did it with a matrix product per azimuth column (1800-2170 of them) and
gathers of (M, 3) arrays, 2-3 ms for an HDL-32E sweep and 10-20 ms for an HDL-64E compensated
one. The arithmetic is numpy's to the bit: a direction's components are fused multiply-adds in
the order x, y, z (what OpenBLAS's sgemm does on this kind of machine, and IEEE's fma gives on
any), the origin and the jitter plain float32 products and sums.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@intrinsic
def _fused(typingctx: Any, a: Any, b: Any, c: Any) -> Any:  # pragma: no cover - compiled
    """a * b + c rounded once (float32)."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        f = args[0].type
        fn = builder.module.declare_intrinsic("llvm.fma", [f], ir.FunctionType(f, [f, f, f]))
        return builder.call(fn, args)

    return sig, codegen


_fma: Any = _fused
"""``_fma(a, b, c)`` in compiled code (the intrinsic, untyped for mypy)."""


@numba.njit(cache=True, nogil=True)
def turn_rays(free: F32, column: NDArray[np.int64], R: F32, t: F32, height: F32, lift: bool,
              noise: F32, sigma: float, rays: F32) -> None:  # pragma: no cover - compiled
    """Fill ``rays`` (M, 6): origin, direction of the M free rays in the world.

    Ray i fires from pose a = ``column[i]`` (or 0 when ``R`` holds one pose): direction
    R[a] ``free[i]`` (+ ``noise[i]`` ``sigma``, unless ``noise`` is empty), origin ``t[a]`` +
    ``height[i]`` R[a][:, 2] (the laser's height along the sensor's z; only with ``lift``).
    free (M, 3), R (A, 3, 3), t (A, 3), height (M,), noise (M, 3) or (0, 3): float32.
    """
    one = R.shape[0] == 1
    jitter = noise.shape[0] > 0
    s = np.float32(sigma)
    for i in range(free.shape[0]):
        a = 0 if one else column[i]
        d0, d1, d2 = free[i, 0], free[i, 1], free[i, 2]
        h = height[i]
        for k in range(3):
            d = _fma(d2, R[a, k, 2], _fma(d1, R[a, k, 1], d0 * R[a, k, 0]))
            if jitter:
                d = d + noise[i, k] * s
            rays[i, 3 + k] = d
            rays[i, k] = t[a, k] + h * R[a, k, 2] if lift else t[a, k]
