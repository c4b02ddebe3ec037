"""Triangle-mesh primitives built with numpy: tubes, height fields, boxes, cylinders, rocks.

Everything is in world coordinates [m], z up. A ``MeshBuilder`` collects parts, each of one
material or one per triangle (``pipeline.sim.materials``); ``build()`` returns (vertices (V, 3)
float64, triangles (T, 3) int64) and ``materials()`` the (T,) uint8 material of every triangle.
Ray casting ignores face orientation, so winding is not kept consistent.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class MeshBuilder:
    """Accumulates mesh parts; ``build()`` concatenates them, ``materials()`` their materials."""

    def __init__(self) -> None:
        self._verts: list[F64] = []
        self._tris: list[I64] = []
        self._mats: list[NDArray[np.uint8]] = []
        self._count = 0

    def add(self, vertices: F64, triangles: I64, material: int | NDArray[np.uint8]) -> None:
        """Append a part: vertices (V, 3), triangles (T, 3) indexing into these vertices, its
        material (a ``Material``, or (T,) one per triangle)."""
        self._verts.append(np.asarray(vertices, np.float64).reshape(-1, 3))
        self._tris.append(np.asarray(triangles, np.int64).reshape(-1, 3) + self._count)
        self._mats.append(np.broadcast_to(np.asarray(material, np.uint8),
                                          (len(self._tris[-1]),)).copy())
        self._count += len(self._verts[-1])

    def materials(self) -> NDArray[np.uint8]:
        """(T,) uint8 material of every triangle of ``build()``."""
        return np.concatenate(self._mats) if self._mats else np.zeros(0, np.uint8)

    def build(self) -> tuple[F64, I64]:
        """(vertices (V, 3) float64, triangles (T, 3) int64) of all parts."""
        if not self._verts:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
        return np.concatenate(self._verts), np.concatenate(self._tris)


def grid_triangles(rows: int, cols: int, wrap_cols: bool = False) -> I64:
    """Triangles of a rows x cols vertex grid (row-major); ``wrap_cols`` closes each row."""
    c = cols if wrap_cols else cols - 1
    r, k = np.meshgrid(np.arange(rows - 1), np.arange(c), indexing="ij")
    a = r * cols + k
    b = r * cols + (k + 1) % cols
    d = (r + 1) * cols + k
    e = (r + 1) * cols + (k + 1) % cols
    return np.concatenate(
        [np.stack([a, b, e], -1).reshape(-1, 3), np.stack([a, e, d], -1).reshape(-1, 3)]
    )


def box(center: F64, size: F64, yaw_rad: float) -> tuple[F64, I64]:
    """An oriented box: centre (3,), size (length x, width y, height z) [m], yaw about z."""
    sx, sy, sz = np.asarray(size, np.float64) / 2
    corners = np.array([[x, y, z] for z in (-sz, sz) for y in (-sy, sy) for x in (-sx, sx)])
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    v = corners @ R.T + np.asarray(center, np.float64)
    quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    tris = [t for a, b, c2, d in quads for t in ((a, b, c2), (a, c2, d))]
    return v, np.array(tris, np.int64)


def cylinder(base: F64, radius: float, height: float, sides: int = 10) -> tuple[F64, I64]:
    """A closed vertical cylinder standing on ``base`` (3,)."""
    th = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([radius * np.cos(th), radius * np.sin(th), np.zeros(sides)], -1)
    top = ring + np.array([0.0, 0.0, height])
    v = np.concatenate([ring, top, [[0.0, 0.0, 0.0], [0.0, 0.0, height]]]) + base
    tris = grid_triangles(2, sides, wrap_cols=True).tolist()
    k = np.arange(sides)
    tris += np.stack([k, (k + 1) % sides, np.full(sides, 2 * sides)], -1).tolist()
    tris += np.stack(
        [k + sides, (k + 1) % sides + sides, np.full(sides, 2 * sides + 1)], -1
    ).tolist()
    return v, np.array(tris, np.int64)


def icosphere(subdivisions: int = 2) -> tuple[F64, I64]:
    """Unit sphere (vertices on the unit sphere, triangles) by subdividing an icosahedron
    (computed once per subdivision level; the caller gets its own copies)."""
    v, f = _icosphere(subdivisions)
    return v.copy(), f.copy()


@functools.lru_cache(maxsize=4)
def _icosphere(subdivisions: int) -> tuple[F64, I64]:
    p = (1 + 5**0.5) / 2
    v = np.array(
        [
            [-1, p, 0],
            [1, p, 0],
            [-1, -p, 0],
            [1, -p, 0],
            [0, -1, p],
            [0, 1, p],
            [0, -1, -p],
            [0, 1, -p],
            [p, 0, -1],
            [p, 0, 1],
            [-p, 0, -1],
            [-p, 0, 1],
        ],
        float,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ]
    )
    verts = list(v / np.linalg.norm(v, axis=1, keepdims=True))
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = np.array(new)
    return np.array(verts), f.astype(np.int64)


def rock(center: F64, radius: float, rng: np.random.Generator,
         subdivisions: int = 2) -> tuple[F64, I64]:
    """A lumpy rock: an icosphere with random radial displacement, flattened a little."""
    v, f = icosphere(subdivisions)
    lumps = 1 + 0.25 * np.sin(v @ rng.normal(size=(3, 4)) * 2 + rng.uniform(0, 6.3, 4)).sum(1) / 2
    v = v * (radius * lumps)[:, None] * np.array([1.0, rng.uniform(0.7, 1.0), 0.7])
    return v + center, f


def add_tree(mb: MeshBuilder, base: F64, rng: np.random.Generator) -> None:
    """A trunk (wood) and a lumpy round crown (vegetation) standing on ``base``, into ``mb``."""
    from pipeline.sim.materials import Material

    h = rng.uniform(2.5, 4.0)
    mb.add(*cylinder(base, rng.uniform(0.15, 0.3), h + 0.5), Material.WOOD)
    mb.add(*rock(np.asarray(base, np.float64) + np.array([0.0, 0.0, h + 1.5]),
                 rng.uniform(1.5, 2.5), rng), Material.VEGETATION)


def height_field(
    x0: float,
    y0: float,
    nx: int,
    ny: int,
    cell_m: float,
    height: Callable[[F64, F64], F64],
    keep: Callable[[F64], NDArray[np.bool_]] | None = None,
) -> tuple[F64, I64]:
    """A terrain grid of nx x ny vertices from (x0, y0), spacing ``cell_m``, z = height(x, y).

    ``keep(centroids_xy (T, 2)) -> (T,) bool`` drops triangles (holes, far cells).
    """
    xs = x0 + np.arange(nx) * cell_m
    ys = y0 + np.arange(ny) * cell_m
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), height(X.ravel(), Y.ravel())], -1)
    t = grid_triangles(nx, ny)
    if keep is not None:
        t = t[keep(v[t, :2].mean(axis=1))]
    used = np.unique(t)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[t]


class SmoothNoise2D:
    """Band-limited 2-D noise: a sum of random plane waves. Call with (x, y) -> z."""

    def __init__(
        self,
        rng: np.random.Generator,
        wavelengths_m: tuple[float, float],
        amplitude_m: float,
        waves: int = 12,
    ) -> None:
        lam = np.exp(rng.uniform(np.log(wavelengths_m[0]), np.log(wavelengths_m[1]), waves))
        ang = rng.uniform(0, 2 * np.pi, waves)
        self.k = (2 * np.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
        self.phase = rng.uniform(0, 2 * np.pi, waves)
        self.amp = amplitude_m * (lam / lam.max()) / np.sqrt(waves / 2)

    def __call__(self, x: F64, y: F64) -> F64:
        arg = np.outer(x, self.k[:, 0]) + np.outer(y, self.k[:, 1]) + self.phase
        return (np.sin(arg) * self.amp).sum(axis=1)
