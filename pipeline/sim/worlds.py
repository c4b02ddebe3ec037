"""Seeded procedural worlds around a route: cave tube, open terrain, street blocks.

``build_world(kind, seed, frames, ...)`` returns a ``World``: one triangle mesh and the
sensor poses (ground truth) of every frame, with the environment label of every frame.
- cave: an irregular tunnel 3-8 m wide along the route (bends of 6-10 m radius, chambers,
  rough walls from band-limited displacement noise, flat rough floor that slopes along);
- open: wide hilly terrain with a few rocks and a tree or two;
- street: nearly flat ground, box buildings of varied frontage, depth and height on both
  sides of the road, parked cars, poles and trees;
- composite: one continuous route through the given segments (default cave, open, street);
  the cave's open end is the mouth into the terrain.
Simulated KITTI (a world along a KITTI ground-truth trajectory) is pipeline/sim/kitti_world.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.sim import meshes
from pipeline.sim.materials import Material
from pipeline.sim.route import (
    DS_M,
    LABELS,
    Poses,
    Route,
    generate_route,
    sample_poses,
    segment_lengths,
    smooth,
)

if TYPE_CHECKING:
    from pipeline.sim.traffic import Traffic

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

WORLDS = ("cave", "open", "street", "composite")
DEFAULT_SEGMENTS = ("cave", "open", "street")
TERRAIN_REACH_M = 80.0
ROAD_CLEARANCE_M = 6.5
ROAD_HALF_WIDTH_M = 4.0
"""Half width of the asphalt along a street segment [m] (material ``ROAD``)."""
WALL_NOISE = ((10, (2.0, 6.0), (1, 6), 0.22), (14, (0.5, 1.5), (4, 18), 0.06))
"""Cave wall displacement: (waves, wavelength range along the tunnel [m], waves around the
ring, amplitude [m]) for the lumps and the knobs."""


@dataclass
class World:
    """A simulated world with its drive: mesh vertices (V, 3) / triangles (T, 3) [m, world
    frame] and the material of every triangle (T,) (``pipeline.sim.materials``), poses (ground
    truth, stamps, label per frame), the route (for plots) and the traffic that moves through
    it (None: a static world)."""

    kind: str
    seed: int
    vertices: F64
    triangles: I64
    materials: NDArray[np.uint8]
    poses: Poses
    route: Route
    traffic: Traffic | None = None

    @property
    def frames(self) -> int:
        return len(self.poses.stamps_ns)


def build_world(
    kind: str,
    seed: int,
    frames: int,
    rate_hz: float = 10.0,
    segments: tuple[str, ...] = DEFAULT_SEGMENTS,
) -> World:
    """The world ``kind`` for ``frames`` frames at ``rate_hz``, all randomness from ``seed``."""
    check_world_args(kind, frames, segments)
    rng = np.random.default_rng([seed, 0])
    labels = list(segments) if kind == "composite" else [kind]
    route, ground, poses = _drive(labels, frames, rate_hz, rng)
    mb = meshes.MeshBuilder()
    if "cave" in [route.labels[i] for i in np.unique(route.label)]:
        for a, b in route.runs("cave"):
            mb.add(*_cave_tube(route, a, b, rng), Material.ROCK)
    if (route.label != LABELS.index("cave")).any():
        mb.add(*_terrain_mesh(route, ground))
        _dress_open(mb, route, ground, rng)
        _dress_street(mb, route, ground, rng)
    vertices, triangles = mb.build()
    return World(kind, seed, vertices, triangles, mb.materials(), poses, route)


ROUTE_ATTEMPTS = 4


def _drive(
    labels: list[str], frames: int, rate_hz: float, rng: np.random.Generator
) -> tuple[Route, _Terrain, Poses]:
    """A route through the segments ``labels``, its ground and ``frames`` poses along it.

    The segment lengths assume each label's own speed, but the speed is smoothed across label
    boundaries, so a short slow segment (a cave) between fast ones (streets) is driven faster
    than planned and the route can end before the last frame. Then the last segment is made
    longer by a quarter of the route and everything is drawn again (from the same generator:
    still one world per seed; worlds that fit at once are unchanged).
    """
    lengths, speeds = segment_lengths(labels, frames, rng, rate_hz)
    for attempt in range(ROUTE_ATTEMPTS):
        route = generate_route(labels, lengths, rng)
        ground = _Terrain(route, rng)
        route.floor_z = _floor_profile(route, ground, rng)
        try:
            return route, ground, sample_poses(route, speeds, frames, rate_hz, rng)
        except ValueError:
            if attempt == ROUTE_ATTEMPTS - 1:
                raise
            lengths[-1] += 0.25 * sum(lengths)
    raise AssertionError("unreachable")  # pragma: no cover


MAX_FRAMES = 100_000
"""The most frames one simulated sequence may have (2.8 hours at 10 Hz)."""


def check_world_args(kind: str, frames: int, segments: tuple[str, ...]) -> None:
    """ConfigError unless the world, frame count (2 .. MAX_FRAMES) and segments make sense."""
    if kind not in WORLDS:
        raise ConfigError(f"unknown world {kind!r} (known: {', '.join(WORLDS)}, kitti)")
    if not 2 <= frames <= MAX_FRAMES:
        raise ConfigError(f"frames must be in [2, {MAX_FRAMES}] (MAX_FRAMES), got {frames}")
    bad = [s for s in segments if s not in LABELS]
    if bad or not segments:
        raise ConfigError(
            f"segments must be a non-empty list of {', '.join(LABELS)}, got {list(segments)}"
        )


# --- ground -------------------------------------------------------------------------------


class _Terrain:
    """Ground height h(x, y): hills and bumps whose amplitudes follow the nearby route labels."""

    def __init__(self, route: Route, rng: np.random.Generator) -> None:
        self.hills = meshes.SmoothNoise2D(rng, (40.0, 160.0), 1.0)
        self.bumps = meshes.SmoothNoise2D(rng, (2.0, 7.0), 1.0, waves=16)
        step = max(1, round(5.0 / DS_M))
        self.anchor_xy = route.xy[::step]
        self.anchor_amp = np.stack(
            [route.style_profile("hills", 40.0), route.style_profile("bumps", 20.0)], -1
        )[::step]
        self.offset = 0.0

    def amplitudes(self, x: F64, y: F64) -> F64:
        """(N, 2) hill and bump amplitude: Gaussian-weighted route anchors (sigma 25 m)."""
        out = np.empty((len(x), 2))
        for i in range(0, len(x), 20000):
            d2 = (x[i : i + 20000, None] - self.anchor_xy[None, :, 0]) ** 2 + (
                y[i : i + 20000, None] - self.anchor_xy[None, :, 1]
            ) ** 2
            w = np.exp(-(d2 - d2.min(axis=1, keepdims=True)) / (2 * 25.0**2))
            out[i : i + 20000] = (w @ self.anchor_amp) / w.sum(axis=1, keepdims=True)
        return out

    def __call__(self, x: F64, y: F64) -> F64:
        x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
        a = self.amplitudes(x, y)
        return self.hills(x, y) * a[:, 0] + self.bumps(x, y) * a[:, 1] + self.offset


def _floor_profile(route: Route, ground: _Terrain, rng: np.random.Generator) -> F64:
    """Floor height of every route sample: the terrain outside caves; inside a cave a floor
    sloping by up to about 9 % that meets the terrain at the cave's open ends."""
    floor = ground(route.xy[:, 0], route.xy[:, 1])
    n = len(route.xy)
    for a, b in route.runs("cave"):
        s = np.arange(b - a) * DS_M
        knots = np.arange(0.0, s[-1] + 12.0, 10.0)
        slope = smooth(np.interp(s, knots, rng.uniform(-0.09, 0.09, len(knots))), 6.0)
        z = np.concatenate([[0.0], np.cumsum(slope[1:] * DS_M)])
        z0 = floor[a - 1] if a > 0 else None
        z1 = floor[b] if b < n else None
        if z0 is not None and z1 is not None and b - a > 1:
            z = z0 + z + (z1 - z0 - z[-1]) * s / s[-1]
        elif z0 is not None:
            z = z0 + z
        elif z1 is not None:
            z = z1 + z - z[-1]
        floor[a:b] = z
    return floor


def _terrain_mesh(route: Route, ground: object,
                  cell_m: float = 1.0) -> tuple[F64, I64, NDArray[np.uint8]]:
    """Ground grid within TERRAIN_REACH_M of the non-cave route, with a hole over caves; its
    material: road within ROAD_HALF_WIDTH_M of a street, ground elsewhere."""
    from scipy.spatial import cKDTree

    cave = route.label == LABELS.index("cave")
    outside = route.xy[~cave][::4]
    lo = np.floor(outside.min(axis=0) - TERRAIN_REACH_M)
    hi = np.ceil(outside.max(axis=0) + TERRAIN_REACH_M)
    tree_all = cKDTree(route.xy[::2])
    cave_sub = cave[::2]
    near_tree = cKDTree(outside)

    def keep(c: F64) -> NDArray[np.bool_]:
        d_out, _ = near_tree.query(c, distance_upper_bound=TERRAIN_REACH_M)
        ok = np.isfinite(d_out)
        d, i = tree_all.query(c)
        return ok & ~(cave_sub[i] & (d < 4.6))

    nx, ny = (int((hi - lo)[k] / cell_m) + 1 for k in range(2))
    v, t = meshes.height_field(lo[0], lo[1], nx, ny, cell_m, ground, keep)  # type: ignore[arg-type]
    d, i = tree_all.query(v[t, :2].mean(axis=1))
    street = route.label[::2][i] == LABELS.index("street")
    road = street & (d < ROAD_HALF_WIDTH_M)
    return v, t, np.where(road, Material.ROAD, Material.GROUND).astype(np.uint8)


# --- cave ---------------------------------------------------------------------------------


def _cave_tube(
    route: Route, a: int, b: int, rng: np.random.Generator, sides: int = 64
) -> tuple[F64, I64]:
    """Tunnel rings along route samples [a, b): width 3-8 m with chambers, rough walls, flat
    rough floor ``route.floor_z``; closed where the route starts or ends inside the cave."""
    m = b - a
    s = np.arange(m, dtype=np.float64) * DS_M
    width = 4.0 + 0.7 * _noise_1d(rng, s, (15.0, 40.0))
    for _ in range(max(1, round(s[-1] / 35.0))):
        c, sig, amp = rng.uniform(0, s[-1]), rng.uniform(2.5, 5.0), rng.uniform(2.0, 3.5)
        width += amp * np.exp(-0.5 * ((s - c) / sig) ** 2)
    width = np.clip(width, 3.0, 8.0)
    height = np.clip(2.6 + 0.35 * (width - 3.0) + 0.3 * _noise_1d(rng, s, (8.0, 25.0)), 2.5, 5.0)
    th = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    rough = _wall_noise(rng, s, th) * (0.6 + 0.08 * width)[:, None]
    heading = route.heading[a:b]
    n_h = np.stack([-np.sin(heading), np.cos(heading)], -1)  # (m, 2) left normal
    floor = route.floor_z[a:b]
    z_c = floor + 0.4 * height
    up = np.where(np.sin(th) > 0, 0.6, 0.4 * 1.7)[None, :] * height[:, None]
    lat = np.cos(th)[None, :] * (0.5 * width[:, None] + rough)
    vert = np.sin(th)[None, :] * (up + rough)
    z = np.maximum(z_c[:, None] + vert, floor[:, None] + 0.15 * rough)
    xy = route.xy[a:b, None, :] + lat[..., None] * n_h[:, None, :]
    v = np.concatenate([xy, z[..., None]], -1).reshape(-1, 3)
    tris = [meshes.grid_triangles(m, sides, wrap_cols=True)]
    centre_v = []
    for ring, closed in ((0, a == 0), (m - 1, b == len(route.xy))):
        if closed:
            centre_v.append(np.concatenate([route.xy[a + ring], [z_c[ring]]]))
            cidx = len(v) + len(centre_v) - 1
            k = np.arange(sides)
            tris.append(
                np.stack(
                    [ring * sides + k, ring * sides + (k + 1) % sides, np.full(sides, cidx)], -1
                )
            )
    if centre_v:
        v = np.concatenate([v, np.array(centre_v)])
    return v, np.concatenate(tris)


def _noise_1d(
    rng: np.random.Generator, x: F64, wavelengths: tuple[float, float], waves: int = 5
) -> F64:
    lam = rng.uniform(*wavelengths, waves)
    ph = rng.uniform(0, 2 * np.pi, waves)
    return np.sin(np.outer(x, 2 * np.pi / lam) + ph).sum(axis=1) / np.sqrt(waves / 2)


def _wall_noise(rng: np.random.Generator, s: F64, th: F64) -> F64:
    """(len(s), len(th)) radial wall displacement [m]: lumps of 2-6 m and knobs of 0.5-1.5 m."""
    out = np.zeros((len(s), len(th)))
    for waves, lam_range, m_range, amp in WALL_NOISE:
        lam = rng.uniform(*lam_range, waves)
        mth = rng.integers(m_range[0], m_range[1] + 1, waves) * rng.choice([-1, 1], waves)
        ph = rng.uniform(0, 2 * np.pi, waves)
        for k in range(waves):
            out += (
                amp
                / np.sqrt(waves / 2)
                * np.sin(2 * np.pi * s[:, None] / lam[k] + mth[k] * th[None, :] + ph[k])
            )
    return out


# --- open space and street dressing ---------------------------------------------------------


def _dress_open(
    mb: meshes.MeshBuilder, route: Route, ground: object, rng: np.random.Generator
) -> None:
    """A few rocks (about one per 25 m) and one or two trees beside every open segment."""
    for a, b in route.runs("open"):
        length = (b - a) * DS_M
        for kind, count in (
            ("rock", max(1, round(length / 25.0))),
            ("tree", int(rng.integers(1, 3))),
        ):
            for _ in range(count):
                i = int(rng.integers(a, b))
                side = rng.choice([-1.0, 1.0])
                off = rng.uniform(4.0, 30.0) if kind == "rock" else rng.uniform(6.0, 25.0)
                n_h = np.array([-np.sin(route.heading[i]), np.cos(route.heading[i])])
                p = route.xy[i] + side * off * n_h
                if _min_dist(route, p[None])[0] < (3.5 if kind == "rock" else 5.0):
                    continue
                z = float(ground(p[:1], p[1:]).item())  # type: ignore[operator]
                if kind == "rock":
                    r = rng.uniform(0.4, 1.8)
                    mb.add(*meshes.rock(np.array([p[0], p[1], z + 0.2 * r]), r, rng),
                           Material.ROCK)
                else:
                    meshes.add_tree(mb, np.array([p[0], p[1], z - 0.3]), rng)


def _dress_street(
    mb: meshes.MeshBuilder, route: Route, ground: object, rng: np.random.Generator
) -> None:
    """Box buildings, parked cars, poles and trees along both sides of every street segment."""
    for a, b in route.runs("street"):
        for side in (-1.0, 1.0):
            _buildings(mb, route, ground, rng, a, b, side)
            _street_items(mb, route, ground, rng, a, b, side)


def _frame_at(route: Route, s_m: float, a: int, b: int) -> tuple[F64, float, F64]:
    i = int(np.clip(round(s_m / DS_M), a, b - 1))
    h = float(route.heading[i])
    return route.xy[i], h, np.array([-np.sin(h), np.cos(h)])


def _buildings(
    mb: meshes.MeshBuilder,
    route: Route,
    ground: object,
    rng: np.random.Generator,
    a: int,
    b: int,
    side: float,
) -> None:
    cursor = a * DS_M + rng.uniform(0, 5)
    while cursor < b * DS_M:
        front = rng.uniform(8.0, 25.0)
        depth, tall = rng.uniform(8.0, 20.0), rng.uniform(5.0, 25.0)
        setback = rng.uniform(7.5, 11.0)
        p, h, n_h = _frame_at(route, cursor + front / 2, a, b)
        c = p + side * (setback + depth / 2) * n_h
        cursor += front + (
            rng.uniform(10.0, 16.0) if rng.random() < 0.15 else rng.uniform(0.5, 4.0)
        )
        if _box_clearance(route, c, front, depth, h) < ROAD_CLEARANCE_M:
            continue
        z0 = float(ground(c[:1], c[1:]).item()) - 1.0  # type: ignore[operator]
        mb.add(
            *meshes.box(
                np.array([c[0], c[1], z0 + (tall + 1.0) / 2]),
                np.array([front, depth, tall + 1.0]),
                h,
            ),
            Material.BUILDING,
        )


def _street_items(
    mb: meshes.MeshBuilder,
    route: Route,
    ground: object,
    rng: np.random.Generator,
    a: int,
    b: int,
    side: float,
) -> None:
    for kind, spacing in (("car", (6.0, 14.0)), ("pole", (15.0, 30.0)), ("tree", (15.0, 35.0))):
        cursor = a * DS_M + rng.uniform(*spacing)
        while cursor < b * DS_M:
            p, h, n_h = _frame_at(route, cursor, a, b)
            cursor += rng.uniform(*spacing)
            if kind == "car":
                if rng.random() < 0.35:
                    continue
                c = p + side * rng.uniform(3.6, 4.4) * n_h
                yaw = h + rng.normal(0, 0.05)
                if _box_clearance(route, c, 4.4, 1.8, yaw) < 2.2:
                    continue
                z = float(ground(c[:1], c[1:]).item())  # type: ignore[operator]
                mb.add(*meshes.box(np.array([c[0], c[1], z + 0.8]), np.array([4.4, 1.8, 1.5]), yaw),
                       Material.VEHICLE)
                continue
            c = p + side * rng.uniform(6.0, 7.0) * n_h
            if _min_dist(route, c[None])[0] < (4.5 if kind == "pole" else 5.5):
                continue
            z = float(ground(c[:1], c[1:]).item())  # type: ignore[operator]
            base = np.array([c[0], c[1], z - 0.2])
            if kind == "pole":
                mb.add(*meshes.cylinder(base, 0.12, rng.uniform(5.0, 8.0), sides=8), Material.METAL)
            elif rng.random() < 0.7:
                meshes.add_tree(mb, base, rng)


def _min_dist(route: Route, p: F64) -> F64:
    """(K,) distance [m] from points p (K, 2) to the nearest route sample."""
    d2 = ((p[:, None, :] - route.xy[None, ::2, :]) ** 2).sum(-1)
    return np.sqrt(d2.min(axis=1))


def _box_clearance(route: Route, c: F64, length: float, width: float, yaw: float) -> float:
    """Distance [m] from the route to the footprint of a box (centre c, yaw)."""
    q = route.xy[::2] - c
    cy, sy = np.cos(yaw), np.sin(yaw)
    qx, qy = q[:, 0] * cy + q[:, 1] * sy, -q[:, 0] * sy + q[:, 1] * cy
    dx = np.maximum(np.abs(qx) - length / 2, 0)
    dy = np.maximum(np.abs(qy) - width / 2, 0)
    return float(np.sqrt(dx**2 + dy**2).min())
