"""The range and normal of every hit, recomputed exactly from the triangle Embree found (numba).

Embree (open3d's RaycastingScene) chooses its kernels by the CPU: SSE, AVX, AVX2 or AVX-512,
and its ray-triangle test divides with the CPU's approximate reciprocal (``rcpps`` and a Newton
step), whose last bits differ between Intel and AMD and between instruction sets. Its ranges
and normals therefore differ between machines in their last bits, and a simulated scan with
them (docs/design.md, "Same numbers on every machine"). Which triangle a ray hits first does not
depend on those bits except for rays within a rounding error of an edge, so the caster keeps
Embree's triangle and recomputes the range to its plane and its unit normal here in float64,
from the float32 vertices and ray Embree was given: the same on every machine.

t = n . (v0 - o) / n . d, n = (v1 - v0) x (v2 - v0), both in float64; a ray parallel to the plane
(n . d = 0, a hit on the triangle's edge seen edge-on) keeps Embree's values.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@numba.njit(cache=True, nogil=True)
def exact_hits(vertices: F32, triangles: NDArray[np.int64], rays: F32, prim: NDArray[np.uint32],
               t: F32, normal: F32) -> None:  # pragma: no cover - compiled
    """In place, for every ray i with a finite ``t[i]``: the range along ``rays[i]`` (M, 6:
    origin, direction, as cast) to the plane of triangle ``prim[i]`` of ``vertices`` (V, 3)
    and ``triangles`` (T, 3), and that triangle's unit normal ``normal[i]`` (M, 3), turned to
    the side of Embree's normal. float32 in and out, float64 in between."""
    for i in range(t.shape[0]):
        if not math.isfinite(t[i]):
            continue
        tri = triangles[prim[i]]
        x0, y0, z0 = (np.float64(vertices[tri[0], 0]), np.float64(vertices[tri[0], 1]),
                      np.float64(vertices[tri[0], 2]))
        ax = np.float64(vertices[tri[1], 0]) - x0
        ay = np.float64(vertices[tri[1], 1]) - y0
        az = np.float64(vertices[tri[1], 2]) - z0
        bx = np.float64(vertices[tri[2], 0]) - x0
        by = np.float64(vertices[tri[2], 1]) - y0
        bz = np.float64(vertices[tri[2], 2]) - z0
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        den = (nx * np.float64(rays[i, 3]) + ny * np.float64(rays[i, 4])
               + nz * np.float64(rays[i, 5]))
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if den == 0.0 or length == 0.0:
            continue
        num = (nx * (x0 - np.float64(rays[i, 0])) + ny * (y0 - np.float64(rays[i, 1]))
               + nz * (z0 - np.float64(rays[i, 2])))
        t[i] = np.float32(num / den)
        if (nx * normal[i, 0] + ny * normal[i, 1] + nz * normal[i, 2]) < 0.0:
            length = -length
        normal[i, 0] = np.float32(nx / length)
        normal[i, 1] = np.float32(ny / length)
        normal[i, 2] = np.float32(nz / length)
