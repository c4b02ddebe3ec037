"""Simulated KITTI: a world along a real KITTI ground-truth trajectory whose environment
changes along the route the way KITTI's does (docs/kitti.md, "Simulated KITTI").

Environments (the label of every frame):
- ``urban``: a canyon of near-continuous facades 12-26 m high, 8.5-11 m from the car, blocks
  of 60 m (cross streets between them), cars parked nose to tail, street lamps, few trees;
- ``residential``: detached houses 6-10 m high, 12-20 m back, gaps between them, hedges
  and fences, many trees, parked cars;
- ``rural``: an open road through rolling fields: hedgerows and shrubs 5-15 m off the road in
  stretches, tree lines and bushes, delineator posts every 50 m, power-line poles, now and
  then a farm building far from the road, terrain that rises and falls beside the road;
- ``highway``: a wide carriageway with a guard rail on the median (posts every 4 m) and a
  guard rail on the verge in stretches only, embankments with shrubs 25-45 m off, a sign now
  and then, far trees. Along the road little but the rails constrains the motion: sequence 01.

The drive is extended by LEAD_M of straight road before its first and after its last pose, so
that a window at either end of a drive has a world behind it too. Every triangle has a
material (``pipeline.sim.materials``): asphalt within the road's half width, soil and grass
beyond, foliage for crowns, hedges and bushes. ``KittiWorldEffects`` adds the soil's roughness,
the road's camber and moving cars (``pipeline.sim.traffic``).

``SCHEDULES`` gives each of the sequences 00-10 a fixed schedule of environments along its
frames, chosen from what each sequence is known to show (01 is KITTI's highway drive, 04 a
straight country road, the others residential and city drives with country stretches;
``SCHEDULE_NOTES``); it is a plausible assignment, not a survey of the real streets.

Deterministic from the seed and independent of the frame window: the route is cut into cells
of ``CELL_M`` metres and every cell draws its objects from its own generator (seed, cell,
side), so a window sees exactly the objects any other window sees at the same place; only the
cells near the window are built. Objects keep clear of every pass of the route (loops).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.errors import ConfigError
from pipeline.sim import meshes
from pipeline.sim.materials import Material
from pipeline.sim.route import DS_M, Poses, Route, route_from_positions
from pipeline.sim.traffic import Traffic, lanes_traffic
from pipeline.sim.worlds import World

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

ENVIRONMENTS = ("urban", "residential", "rural", "highway")

SCHEDULES: dict[str, tuple[tuple[int, str], ...]] = {
    "00": ((0, "residential"), (400, "urban"), (900, "residential"), (1500, "urban"),
           (1900, "residential"), (2700, "urban"), (3100, "residential"), (3900, "urban"),
           (4200, "residential")),
    "01": ((0, "highway"),),
    "02": ((0, "residential"), (600, "rural"), (1500, "residential"), (2100, "rural"),
           (3000, "residential"), (3500, "rural"), (4200, "residential")),
    "03": ((0, "rural"), (350, "residential"), (600, "rural")),
    "04": ((0, "rural"),),
    "05": ((0, "residential"), (700, "urban"), (1100, "residential"), (1900, "urban"),
           (2300, "residential")),
    "06": ((0, "residential"), (350, "rural"), (750, "residential")),
    "07": ((0, "urban"), (400, "residential"), (800, "urban")),
    "08": ((0, "residential"), (600, "urban"), (1100, "residential"), (1800, "rural"),
           (2300, "residential"), (3000, "urban"), (3500, "residential")),
    "09": ((0, "residential"), (500, "rural"), (1100, "residential")),
    "10": ((0, "rural"), (400, "residential"), (900, "rural")),
}
"""Sequence -> ((first KITTI frame, environment), ...): the environment from that frame on."""

SCHEDULE_NOTES = {
    "00": "Karlsruhe residential streets with loops, some denser city blocks",
    "01": "the Autobahn drive (KITTI raw 'road'), 21.5 m/s on average: highway throughout",
    "02": "the longest drive, residential streets and country roads in turn",
    "03": "a country road through a village",
    "04": "a straight road through open country at 14 m/s",
    "05": "residential streets with loops, some denser blocks",
    "06": "a wide residential street out and back, open land at the far end",
    "07": "slow city driving: dense blocks and residential streets",
    "08": "residential and city streets, one country stretch",
    "09": "suburb to countryside and back",
    "10": "country roads and a village",
}

CELL_M = 60.0
"""Length of route per generator cell [m] (also the urban block length)."""
REACH_M = 110.0
"""The world is built within this distance of the window's route [m] (HDL-64E: 120 m)."""
MARGIN_M = 120.0
"""Route before the window's first and after its last frame that is dressed too [m]."""
LEAD_M = 150.0
"""Straight road added before a drive's first and after its last pose [m] (``_with_lead``)."""
LIDAR_HEIGHT_M = 1.73
"""KITTI's velodyne above the road [m]."""
GROUND_AMPLITUDE_M = {"urban": 0.0, "residential": 0.3, "rural": 2.0, "highway": 1.5}
"""Amplitude of the ground's undulation beside the road, by environment [m]."""
ROAD_HALF_WIDTH_M = {"urban": 6.0, "residential": 4.5, "rural": 3.5, "highway": 8.0}
"""Half width of the asphalt around the route, by environment [m]."""
CORRIDOR_M = 9.0
"""Half width of the flat road corridor [m]; the undulation grows over the next 15 m."""


@dataclass(frozen=True)
class Ground:
    """Height of the ground h(x, y) [m]: the road's height (inverse-distance weighted floor of
    the nearest route samples), plus beside the road an undulation whose amplitude follows
    the environment of the nearest route sample (fields and embankments in the country)."""

    route: Route
    tree: object  # scipy cKDTree over route.xy
    noise: meshes.SmoothNoise2D
    roughness: meshes.SmoothNoise2D
    """Unit-amplitude height noise of 1.5-6 m wavelengths (scaled by ``effects``)."""
    effects: KittiWorldEffects

    def __call__(self, x: F64, y: F64) -> F64:
        xy = np.stack([np.ravel(x), np.ravel(y)], -1)
        d, i = self.tree.query(xy, k=8)  # type: ignore[attr-defined]
        w = 1.0 / (d + 5.0) ** 2
        z = (self.route.floor_z[i] * w).sum(axis=1) / w.sum(axis=1)
        label = self.route.label[i[:, 0]]
        amp = np.array([GROUND_AMPLITUDE_M[e] for e in ENVIRONMENTS])[label]
        rise = np.clip((d[:, 0] - CORRIDOR_M) / 15.0, 0.0, 1.0)
        z = z + amp * rise * (self.noise(xy[:, 0], xy[:, 1]) + 0.5)
        half = np.array([ROAD_HALF_WIDTH_M[e] for e in ENVIRONMENTS])[label]
        e = self.effects
        if e.road_cross_slope > 0.0:  # the crown at the route, falling to both edges
            z = z - e.road_cross_slope * np.minimum(d[:, 0], half)
        if e.ground_roughness_m > 0.0:  # beyond the asphalt (a metre to blend in)
            off_road = np.clip(d[:, 0] - half, 0.0, 1.0)
            z = z + e.ground_roughness_m * off_road * self.roughness(xy[:, 0], xy[:, 1])
        return z


class KittiWorldEffects(Section):
    """What the simulated-KITTI world adds to its geometry (docs/simulator.md, "World
    effects"): ``ground_roughness_m`` sigma of the height of the soil and grass beside the
    road (wavelengths 1.5-6 m; 0 = smooth), ``road_cross_slope`` the road's fall from its crown
    to the edges (0.025: German guidelines), ``traffic`` moving cars in the other lanes
    (``pipeline/sim/traffic.py``)."""

    ground_roughness_m: float = Field(0.05, ge=0.0, le=1.0)
    road_cross_slope: float = Field(0.025, ge=0.0, le=0.1)
    traffic: bool = True


def frame_environments(sequence: str, frames: int) -> list[str]:
    """The environment of every frame 0..frames-1 of KITTI ``sequence`` (``SCHEDULES``)."""
    if sequence not in SCHEDULES:
        raise ConfigError(f"no environment schedule for KITTI sequence {sequence!r} "
                          f"(known: {', '.join(SCHEDULES)})")
    firsts = [first for first, _ in SCHEDULES[sequence]]
    envs = [env for _, env in SCHEDULES[sequence]]
    index = np.searchsorted(firsts, np.arange(frames), side="right") - 1
    return [envs[i] for i in index]


@dataclass
class KittiDrive:
    """A KITTI trajectory as a labelled route: every frame's pose, stamp, environment and arc
    length [m] along the route, and the route itself (labels = ENVIRONMENTS)."""

    T_world_lidar: F64
    stamps_ns: NDArray[np.int64]
    environments: list[str]
    s_frame: F64
    route: Route


def kitti_drive(trajectory: Path, sequence: str) -> KittiDrive:
    """The labelled route of the ground-truth file ``trajectory`` of KITTI ``sequence``."""
    from pipeline.sim.kitti import kitti_lidar_poses

    T, stamps = kitti_lidar_poses(trajectory)
    envs = frame_environments(sequence, len(T))
    step = np.linalg.norm(np.diff(T[:, :2, 3], axis=0), axis=1)
    s_frame = LEAD_M + np.concatenate([[0.0], np.cumsum(step)])
    route = route_from_positions(_with_lead(T), height_m=LIDAR_HEIGHT_M)
    frame_of_sample = np.clip(np.searchsorted(s_frame, route.s, side="right") - 1, 0, len(T) - 1)
    env_idx = np.array([ENVIRONMENTS.index(e) for e in envs])
    route = Route(route.xy, route.heading, env_idx[frame_of_sample], ENVIRONMENTS, route.floor_z)
    return KittiDrive(T, stamps, envs, s_frame, route)


def _with_lead(T: F64) -> F64:
    """The sensor positions (N + 2 K, 3) of poses ``T`` with LEAD_M of straight road before
    the first (along its heading) and after the last, so that a window at either end of a
    drive has a world around it too (the real car came from somewhere)."""
    k = np.arange(LEAD_M, 0.0, -DS_M)[:, None]
    head0, head1 = T[0, :3, 0] * [1, 1, 0], T[-1, :3, 0] * [1, 1, 0]
    before = T[0, :3, 3] - k * head0 / np.linalg.norm(head0)
    after = T[-1, :3, 3] + k[::-1] * head1 / np.linalg.norm(head1)
    return np.concatenate([before, T[:, :3, 3], after])


@dataclass
class _Site:
    """What the dressers need: the labelled route, a KD-tree over all its samples (clearance
    from every pass), the ground, and the route's left normals (M, 2)."""

    route: Route
    tree: object
    ground: Ground
    normal: F64

    def at(self, s_m: float) -> tuple[F64, float, F64, float]:
        """(xy (2,), heading [rad], left normal (2,), floor z [m]) of the route at ``s_m``."""
        i = int(np.clip(round(s_m / DS_M), 0, len(self.route.xy) - 1))
        return self.route.xy[i], float(self.route.heading[i]), self.normal[i], float(
            self.route.floor_z[i])

    def clearance(self, centre: F64, length: float, width: float, yaw: float) -> float:
        """Distance [m] from the route (every pass) to a footprint (centre, size, yaw)."""
        nx, ny = max(2, int(np.ceil(length / 1.5)) + 1), max(2, int(np.ceil(width / 1.5)) + 1)
        u, v = np.meshgrid(np.linspace(-length / 2, length / 2, nx),
                           np.linspace(-width / 2, width / 2, ny), indexing="ij")
        c, s = np.cos(yaw), np.sin(yaw)
        pts = np.stack([centre[0] + c * u.ravel() - s * v.ravel(),
                        centre[1] + s * u.ravel() + c * v.ravel()], -1)
        d, _ = self.tree.query(pts)  # type: ignore[attr-defined]
        return float(d.min())

    def z(self, xy: F64) -> float:
        return float(self.ground(xy[:1], xy[1:]).item())


def check_kitti_args(trajectory: Path | None, start: int, frames: int) -> None:
    """ConfigError unless ``trajectory`` is a KITTI ground-truth file NN.txt of a sequence with
    an environment schedule and ``start`` .. ``start + frames - 1`` a window of its frames."""
    from pipeline.sim.kitti import kitti_lidar_poses

    if trajectory is None:
        raise ConfigError("--world kitti needs --kitti-trajectory NN.txt")
    sequence = Path(trajectory).stem
    if sequence not in SCHEDULES:
        raise ConfigError(f"{trajectory}: the simulated-KITTI world is known for NN.txt of "
                          f"the sequences {', '.join(SCHEDULES)}, got {Path(trajectory).name!r}")
    if start < 0 or frames < 2:
        raise ConfigError(f"--start must be >= 0 and --frames >= 2, got (start={start}, "
                          f"frames={frames})")
    count = len(kitti_lidar_poses(trajectory)[0])
    if start + frames > count:
        raise ConfigError(f"{trajectory} has {count} poses: frames {start}..{start + frames - 1} "
                          "are not a window of them")


def build_kitti_world(trajectory: Path, sequence: str, seed: int, first: int,
                      last: int, effects: KittiWorldEffects | None = None) -> World:
    """The simulated-KITTI world of frames ``first`` .. ``last`` (inclusive) of ``sequence``
    driven along ``trajectory`` (its ground-truth file)."""
    from scipy.spatial import cKDTree

    drive = kitti_drive(trajectory, sequence)
    if not 0 <= first < last < len(drive.T_world_lidar):
        raise ConfigError(f"{trajectory}: frames {first}..{last} are not a window of its "
                          f"{len(drive.T_world_lidar)} frames")
    route = drive.route
    normal = np.stack([-np.sin(route.heading), np.cos(route.heading)], -1)
    effects = effects or KittiWorldEffects.model_validate({})
    ground = Ground(route, cKDTree(route.xy),
                    meshes.SmoothNoise2D(np.random.default_rng([seed, 3]), (25.0, 90.0), 1.0),
                    meshes.SmoothNoise2D(np.random.default_rng([seed, 5]), (1.5, 6.0), 1.0,
                                         waves=24), effects)
    site = _Site(route, ground.tree, ground, normal)
    lo = max(0.0, drive.s_frame[first] - MARGIN_M)
    hi = min(route.s[-1], drive.s_frame[last] + MARGIN_M)
    near = (route.s >= lo) & (route.s <= hi)
    mb = meshes.MeshBuilder()
    mb.add(*_terrain(site, near))
    for cell in _cells_near(route, near):
        _dress_cell(mb, site, cell, seed)
    vertices, triangles = mb.build()
    poses = Poses(drive.T_world_lidar[first:last + 1], drive.stamps_ns[first:last + 1],
                  drive.environments[first:last + 1])
    traffic = (kitti_traffic(drive, _cells_near(route, near), seed) if effects.traffic
               else None)
    return World("kitti", seed, vertices, triangles, mb.materials(), poses, route, traffic)


TRAFFIC = {"urban": (12.0, (8.0, 14.0)), "residential": (5.0, (6.0, 12.0)),
           "rural": (4.0, (14.0, 25.0)), "highway": (10.0, (25.0, 36.0))}
"""Environment -> (vehicles a km and lane, speed range [m/s]) of the traffic."""
LANES_M = {"urban": (3.5,), "residential": (3.5,), "rural": (3.5,),
           "highway": (3.75, 11.0)}
"""Lanes with traffic, left of the car's lane [m]: the oncoming lane; on the highway the
overtaking lane (same direction) and the far carriageway's lane (oncoming)."""


def kitti_traffic(drive: KittiDrive, cells: list[int], seed: int) -> Traffic:
    """The moving cars of the route ``cells``: in every cell and lane (``LANES_M``) a Poisson
    number of cars (``TRAFFIC``) placed where they are when the car passes the cell's
    centre, each at its own speed; one generator per (seed, cell)."""
    route = drive.route
    t_frame = (drive.stamps_ns - drive.stamps_ns[0]) * 1e-9
    lateral, s_then, speed, t_then = [], [], [], []
    for cell in cells:
        rng = np.random.default_rng([seed, 13, cell])
        centre = (cell + 0.5) * CELL_M
        i = int(np.clip(round(centre / DS_M), 0, len(route.xy) - 1))
        density, speeds = TRAFFIC[ENVIRONMENTS[int(route.label[i])]]
        env = ENVIRONMENTS[int(route.label[i])]
        when = float(np.interp(centre, drive.s_frame, t_frame))
        for k, lane in enumerate(LANES_M[env]):
            count = rng.poisson(density * CELL_M / 1000.0)
            oncoming = k == len(LANES_M[env]) - 1
            lateral += [lane] * count
            s_then += list(rng.uniform(cell * CELL_M, (cell + 1) * CELL_M, count))
            v = rng.uniform(*speeds, count)
            speed += list(-v if oncoming else v)
            t_then += [when] * count
    return lanes_traffic(route, np.array(lateral), np.array(s_then), np.array(speed),
                         np.array(t_then))


def _cells_near(route: Route, near: NDArray[np.bool_]) -> list[int]:
    """Cells with a route sample within REACH_M of the ``near`` samples (every pass)."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(route.xy[near][::4]).query(route.xy, distance_upper_bound=REACH_M)
    return sorted(set((route.s[np.isfinite(d)] // CELL_M).astype(int).tolist()))


def _terrain(site: _Site, near: NDArray[np.bool_],
             cell_m: float = 1.0) -> tuple[F64, I64, NDArray[np.uint8]]:
    """The ground within REACH_M of the ``near`` route samples, a grid of ``cell_m`` [m], and
    its material: asphalt within the road's half width (``ROAD_HALF_WIDTH_M``) of the route,
    ground beyond."""
    from scipy.spatial import cKDTree

    xy = site.route.xy[near]
    # on a grid anchored at the origin, so that every window shares its vertices
    lo = np.floor((xy.min(axis=0) - REACH_M) / cell_m) * cell_m
    hi = np.ceil((xy.max(axis=0) + REACH_M) / cell_m) * cell_m
    tree = cKDTree(xy[::4])

    def keep(c: F64) -> NDArray[np.bool_]:
        d, _ = tree.query(c, distance_upper_bound=REACH_M)
        return np.isfinite(d)

    nx, ny = (round((hi - lo)[k] / cell_m) + 1 for k in range(2))
    v, t = meshes.height_field(lo[0], lo[1], nx, ny, cell_m, site.ground, keep)  # type: ignore[arg-type]
    d, i = site.tree.query(v[t, :2].mean(axis=1))  # type: ignore[attr-defined]
    half = np.array([ROAD_HALF_WIDTH_M[e] for e in ENVIRONMENTS])[site.route.label[i]]
    return v, t, np.where(d < half, Material.ROAD, Material.GROUND).astype(np.uint8)


def _dress_cell(mb: meshes.MeshBuilder, site: _Site, cell: int, seed: int) -> None:
    """The objects of route cell ``cell`` on both sides, by the environment of each stretch;
    one generator per (seed, cell, side), so that the cell never depends on the window."""
    route = site.route
    a = int(cell * CELL_M / DS_M)
    b = min(len(route.xy), int((cell + 1) * CELL_M / DS_M))
    labels = route.label[a:b]
    cuts = np.flatnonzero(np.diff(labels)) + 1
    runs = list(zip([0, *cuts.tolist()], [*cuts.tolist(), b - a], strict=True))
    for side in (-1.0, 1.0):
        rng = np.random.default_rng([seed, 7, cell, int(side > 0)])
        for r0, r1 in runs:
            env = ENVIRONMENTS[int(labels[r0])]
            DRESSERS[env](mb, site, (a + r0) * DS_M, (a + r1) * DS_M, side, rng)


# --- dressing: one function per environment, over the arc [s0, s1) [m] on one side ---------


def _box(mb: meshes.MeshBuilder, site: _Site, s: float, lateral: float, size: tuple[float, ...],
         side: float, clearance: float, material: Material, yaw_jitter: float = 0.0) -> bool:
    """A box of ``material`` (length along the road, width across, height) whose near edge is
    ``lateral`` metres from the route at arc ``s``, standing on the ground (sunk 0.5 m); False
    when it would come closer than ``clearance`` to the route."""
    p, h, n, _ = site.at(s)
    length, width, height = size
    c = p + side * (lateral + width / 2) * n
    yaw = h + yaw_jitter
    if site.clearance(c, length, width, yaw) < clearance:
        return False
    z0 = site.z(c) - 0.5
    mb.add(*meshes.box(np.array([c[0], c[1], z0 + (height + 0.5) / 2]),
                       np.array([length, width, height + 0.5]), yaw), material)
    return True


def _facades(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
             rng: np.random.Generator, front: tuple[float, float], depth: tuple[float, float],
             tall: tuple[float, float], setback: tuple[float, float],
             gap: tuple[float, float], hedge: float = 0.0) -> None:
    """Buildings along [s0, s1): frontage, depth, height, setback (near facade from the
    route) and gap ranges [m]; with probability ``hedge`` a hedge or fence before each."""
    s = s0 + rng.uniform(0.0, 3.0)
    while True:
        f = min(rng.uniform(*front), s1 - 1.0 - s)  # the last one fills the block
        if f < 0.5 * front[0]:
            break
        back = rng.uniform(*setback)
        _box(mb, site, s + f / 2, back, (f, rng.uniform(*depth), rng.uniform(*tall)), side, 7.0,
             Material.BUILDING)
        g = rng.uniform(*gap)
        if rng.random() < hedge:
            _box(mb, site, s + (f + g) / 2, back - rng.uniform(2.0, 4.0),
                 (f + 0.8 * g, 0.6, rng.uniform(0.8, 1.6)), side, 4.5, Material.VEGETATION)
        s += f + g


def _along(site: _Site, s0: float, s1: float, rng: np.random.Generator,
           spacing: tuple[float, float]) -> list[float]:
    """Arc positions [m] in [s0, s1) at random spacings."""
    out, s = [], s0 + rng.uniform(0.0, spacing[1])
    while s < s1:
        out.append(s)
        s += rng.uniform(*spacing)
    return out


def _cars(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
          rng: np.random.Generator, spacing: tuple[float, float], p: float) -> None:
    """Parked cars (4.4 x 1.8 x 1.5 m), their centres 3.2-4 m beside the route."""
    for s in _along(site, s0, s1, rng, spacing):
        if rng.random() < p:
            _box(mb, site, s, rng.uniform(2.3, 3.1), (4.4, 1.8, 1.5), side, 2.2,
                 Material.VEHICLE, rng.normal(0.0, 0.04))


def _poles(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
           rng: np.random.Generator, spacing: tuple[float, float], lateral: tuple[float, float],
           height: tuple[float, float]) -> None:
    """Street lamps or power-line poles (cylinders 0.12-0.15 m in radius)."""
    for s in _along(site, s0, s1, rng, spacing):
        p, _, n, _ = site.at(s)
        c = p + side * rng.uniform(*lateral) * n
        if site.clearance(c, 0.3, 0.3, 0.0) > 3.5:
            mb.add(*meshes.cylinder(np.array([c[0], c[1], site.z(c) - 0.2]),
                                    rng.uniform(0.12, 0.15), rng.uniform(*height), sides=8),
                   Material.METAL)


def _trees(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
           rng: np.random.Generator, spacing: tuple[float, float], p: float,
           lateral: tuple[float, float]) -> None:
    """Trees (trunk and crown) at random spacings and distances from the route."""
    for s in _along(site, s0, s1, rng, spacing):
        if rng.random() >= p:
            continue
        pos, _, n, _ = site.at(s)
        c = pos + side * rng.uniform(*lateral) * n
        if site.clearance(c, 0.5, 0.5, 0.0) > 4.5:
            meshes.add_tree(mb, np.array([c[0], c[1], site.z(c) - 0.3]), rng)


def _hedgerow(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
              rng: np.random.Generator, lateral: tuple[float, float],
              radius: tuple[float, float]) -> None:
    """Stretches (15-50 m, gaps of 3-15 m) of hedge or shrub along [s0, s1): overlapping
    lumpy blobs of foliage (``radius`` [m]) ``lateral`` metres from the route, wandering by
    half a metre."""
    s = s0 + rng.uniform(0.0, 10.0)
    base = rng.uniform(*lateral)
    while s < s1:
        end = min(s1, s + rng.uniform(15.0, 50.0))
        while s < end:
            r = rng.uniform(*radius)
            p, _, n, _ = site.at(s)
            c = p + side * (base + rng.uniform(-0.5, 0.5) + r) * n
            if site.clearance(c, 2 * r, 2 * r, 0.0) > 3.5:
                mb.add(*meshes.rock(np.array([c[0], c[1], site.z(c) + 0.4 * r]), r, rng, 1),
                       Material.VEGETATION)
            s += rng.uniform(0.8, 1.2) * r
        s = end + rng.uniform(3.0, 15.0)


def _urban(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
           rng: np.random.Generator) -> None:
    _facades(mb, site, s0, s1, side, rng, front=(12.0, 28.0), depth=(10.0, 18.0),
             tall=(12.0, 26.0), setback=(8.5, 11.0), gap=(0.0, 1.5))
    _cars(mb, site, s0, s1, side, rng, (5.2, 7.5), 0.75)
    _poles(mb, site, s0, s1, side, rng, (20.0, 30.0), (6.0, 7.0), (6.0, 8.0))
    _trees(mb, site, s0, s1, side, rng, (15.0, 30.0), 0.3, (6.0, 7.5))


def _residential(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
                 rng: np.random.Generator) -> None:
    _facades(mb, site, s0, s1, side, rng, front=(8.0, 14.0), depth=(8.0, 12.0),
             tall=(6.0, 10.0), setback=(12.0, 20.0), gap=(5.0, 15.0), hedge=0.5)
    _cars(mb, site, s0, s1, side, rng, (7.0, 15.0), 0.5)
    _poles(mb, site, s0, s1, side, rng, (25.0, 40.0), (5.5, 6.5), (5.0, 7.0))
    _trees(mb, site, s0, s1, side, rng, (6.0, 14.0), 0.75, (6.0, 11.0))


def _delineators(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
                 lateral: float) -> None:
    """Delineator posts (0.12 x 0.1 x 1 m) every DELINEATOR_M metres of route, ``lateral``
    metres from the route (German rural roads and motorways: RPS / Leitpfosten)."""
    for s in np.arange(np.ceil(s0 / DELINEATOR_M) * DELINEATOR_M, s1, DELINEATOR_M):
        p, h, n, _ = site.at(float(s))
        c = p + side * lateral * n
        mb.add(*meshes.box(np.array([c[0], c[1], site.z(c) + 0.45]),
                           np.array([0.12, 0.1, 1.1]), h), Material.METAL)


def _rural(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
           rng: np.random.Generator) -> None:
    _delineators(mb, site, s0, s1, side, ROAD_HALF_WIDTH_M["rural"] + 0.5)
    if rng.random() < 0.6:
        _hedgerow(mb, site, s0, s1, side, rng, (5.0, 15.0), (0.8, 1.6))
    _trees(mb, site, s0, s1, side, rng, (6.0, 16.0), 0.6, (6.0, 14.0))
    _trees(mb, site, s0, s1, side, rng, (20.0, 60.0), 0.7, (20.0, 70.0))
    for s in _along(site, s0, s1, rng, (15.0, 40.0)):  # bushes
        p, _, n, _ = site.at(s)
        c = p + side * rng.uniform(5.0, 15.0) * n
        r = rng.uniform(0.5, 1.3)
        if site.clearance(c, 2 * r, 2 * r, 0.0) > 4.0:
            mb.add(*meshes.rock(np.array([c[0], c[1], site.z(c) + 0.2 * r]), r, rng),
                   Material.VEGETATION)
    _poles(mb, site, s0, s1, side, rng, (35.0, 50.0), (5.0, 6.5), (7.0, 9.0))
    if rng.random() < 0.15 * (s1 - s0) / CELL_M:  # a farm building
        _box(mb, site, rng.uniform(s0, s1), rng.uniform(25.0, 60.0),
             (rng.uniform(15.0, 30.0), rng.uniform(10.0, 20.0), rng.uniform(5.0, 9.0)),
             side, 20.0, Material.BUILDING)


DELINEATOR_M = 50.0
"""Spacing of delineator posts along rural roads [m]."""
RAIL_M = (0.45, 0.8)
"""Guard rail beam: bottom and top above the road [m]."""
RAIL_POST_M = 4.0


def _highway(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, side: float,
             rng: np.random.Generator) -> None:
    """The median rail (left, 7 m) throughout; the verge rail (right, 5.5 m) in about half of
    the cells; a sign in about one cell side in ten; a tree or bush or two far off."""
    if side > 0 or rng.random() < 0.5:
        _rail(mb, site, s0, s1, side * (7.0 if side > 0 else 5.5))
    if side < 0 and rng.random() < 0.1:
        p, h, n, z = site.at(rng.uniform(s0, s1))
        c = p - 8.0 * n
        for off in (-1.2, 1.2):
            base = np.array([c[0] + off * np.cos(h), c[1] + off * np.sin(h), z - 0.2])
            mb.add(*meshes.cylinder(base, 0.08, 4.5, sides=6), Material.METAL)
        mb.add(*meshes.box(np.array([c[0], c[1], z + 4.5]), np.array([3.2, 0.1, 2.0]), h),
               Material.METAL)
    if rng.random() < 0.5:  # shrubs at the top of the embankment
        _hedgerow(mb, site, s0, s1, side, rng, (25.0, 45.0), (1.0, 2.0))
    _trees(mb, site, s0, s1, side, rng, (40.0, 120.0), 0.6, (15.0, 50.0))


def _rail(mb: meshes.MeshBuilder, site: _Site, s0: float, s1: float, offset: float) -> None:
    """A guard rail ``offset`` metres left (+) or right (-) of the route along [s0, s1): a
    beam as a vertical strip every metre, and posts every RAIL_POST_M metres of the route
    behind it (as real guard rails: the beam hides the posts but below it)."""
    route = site.route
    i = np.arange(int(s0 / DS_M), min(len(route.xy), int(s1 / DS_M) + 1), max(1, round(1 / DS_M)))
    if len(i) < 2:
        return
    xy = route.xy[i] + offset * site.normal[i]
    z = route.floor_z[i]
    v = np.concatenate([np.column_stack([xy, z + RAIL_M[0]]), np.column_stack([xy, z + RAIL_M[1]])])
    strip = meshes.grid_triangles(2, len(i))
    mb.add(v, strip, Material.METAL)
    for s in np.arange(np.ceil(s0 / RAIL_POST_M) * RAIL_POST_M, s1, RAIL_POST_M):
        p, h, n, z0 = site.at(float(s))
        c = p + (offset + np.sign(offset) * 0.15) * n  # behind the beam, seen below it
        mb.add(*meshes.box(np.array([c[0], c[1], z0 + RAIL_M[1] / 2 - 0.1]),
                           np.array([0.12, 0.12, RAIL_M[1] + 0.2]), h), Material.METAL)


DRESSERS = {"urban": _urban, "residential": _residential, "rural": _rural, "highway": _highway}


def change_window(sequence: str, frames: int, length: int) -> tuple[int, int]:
    """(first, last) frame of a ``length``-frame window of ``sequence`` (``frames`` frames)
    around its first change of environment (two fifths of the window before it), or its first
    ``length`` frames when the schedule has no change: a short window that still shows the
    environment change along the route."""
    schedule = SCHEDULES[sequence]
    start = max(0, schedule[1][0] - 2 * length // 5) if len(schedule) > 1 else 0
    start = max(0, min(start, frames - length))
    return start, min(frames, start + length) - 1
