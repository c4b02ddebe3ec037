"""Ray casting a sensor model against a world mesh (open3d RaycastingScene, Embree).

``scan``: all rays of a scan (beams x azimuths) are cast at once from the frame's pose: an
instantaneous scan. ``sweep``: the azimuth columns are fired one after the other over the
sweep, each from the pose at its own time (linear in translation, slerp in rotation between
the sweep's start and end poses), so the points carry the motion distortion of a real spinning
sensor and each gets its time; ``compensate`` then moves every point into the frame of the
sweep's start (the ego-motion compensation KITTI's odometry files had, with exact poses).

Every scan has a random azimuth phase (a free-running sensor). The sensor's effects
(``pipeline.sim.effects.SensorEffects``; docs/simulator.md, "Sensor effects") are applied to
the rays and returns: lasers from their own origins (``heights_m``) at their true elevations
(the unit's calibration errors) with per-firing jitter, the car's hidden sectors never fired,
foliage entered by the beam, returns kept with a probability from reflectance, incidence and
range, range noise from range and incidence plus each laser's range offset. The point is then
placed where the sensor believes the ray went (reported elevation, no jitter); its intensity is
reflectance x cos(incidence). Moving objects (``movers``: a mesh at the scan's time) are cast
beside the static world.

The per-ray work is compiled (``rays_kernel``, ``relief_kernel``, ``returns_kernel``) and a
scan uses ``threads`` threads (open3d's casting, the returns' kernels); its points do not
depend on how many (docs/simulator.md, "Speed").
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.executor import process_threads
from pipeline.sim.effects import SensorEffects
from pipeline.sim.hits_kernel import exact_hits
from pipeline.sim.materials import Material, reflectance_table, relief_table
from pipeline.sim.rays_kernel import turn_rays
from pipeline.sim.relief_kernel import lay_relief, rough_hits, row_sums
from pipeline.sim.returns_kernel import draw_uniforms, kept_rows, shape_returns
from pipeline.sim.sensors import SensorModel

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
REFLECTANCE = reflectance_table()
RELIEF = relief_table()
_NO_NOISE = np.zeros((0, 3), np.float32)
VEGETATION_STEP_M = 0.01
"""How far past a foliage surface a ray is cast again [m]."""


@dataclass(frozen=True)
class Hits:
    """Returns of M rays: range [m] (inf: none), unit normal (M, 3) and material (M,)."""

    t: F32
    normal: F32
    material: NDArray[np.uint8]


class Raycaster:
    """Casts scans of ``sensor`` against one mesh (``materials``: (T,) uint8 per triangle,
    default ground; ``world_seed``: of the surfaces' relief; ``threads``: of one scan, default
    ``pipeline.executor.process_threads()``: every CPU in a main process, 1 in a pool worker
    of a 2-core machine). Build once per world, call ``scan`` or ``sweep`` per frame. The
    points do not depend on ``threads``.

    The mesh is shifted to a local origin so that float32 ray casting keeps mm precision
    far from the world origin.
    """

    def __init__(self, vertices: F64, triangles: NDArray[np.int64], sensor: SensorModel,
                 materials: NDArray[np.uint8] | None = None, world_seed: int = 0,
                 threads: int | None = None) -> None:
        import open3d as o3d

        self.sensor = sensor
        self.origin = np.round(vertices.mean(axis=0)) if len(vertices) else np.zeros(3)
        self._vertices = (vertices - self.origin).astype(np.float32)
        self._triangles = np.ascontiguousarray(triangles, dtype=np.int64)
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(self._vertices),  # type: ignore[call-overload]
            o3d.core.Tensor(self._triangles.astype(np.uint32)),  # type: ignore[call-overload]
        )
        self._o3d = o3d
        self.materials = (np.full(len(triangles), Material.GROUND, np.uint8) if materials is None
                          else np.asarray(materials, np.uint8))
        self._beam = _BeamGeometry(sensor)
        self._bumps = Relief(np.random.default_rng([world_seed, 73]))
        self._settings = _settings(sensor.effects, sensor.min_range_m, sensor.max_range_m)
        self.threads = process_threads() if threads is None else threads
        if self.threads < 1:
            raise ConfigError(f"threads must be >= 1, got {self.threads}")

    def scan(self, T_world_lidar: F64, rng: np.random.Generator,
             movers: tuple[F64, NDArray[np.int64]] | None = None) -> F32:
        """(N, 4) float32 points [m] in the lidar frame + intensity in [0, 1]."""
        with _one_blas_thread():
            return self._scan(T_world_lidar[None], rng, movers, compensate=False)[0]

    def sweep(self, T_start: F64, T_end: F64, rng: np.random.Generator,
              movers: tuple[F64, NDArray[np.int64]] | None = None,
              compensate: bool = False) -> tuple[F32, F32]:
        """A motion-distorted scan: ((N, 4) float32 points in the lidar frame at each point's
        firing time + intensity, (N,) float32 firing time [s] after the sweep's start);
        ``compensate``: the points in the frame at the sweep's start instead.

        Column a of the A azimuth columns fires at a / A of the sweep (1 / rate_hz s), from the
        pose interpolated between ``T_start`` (the stamp) and ``T_end`` (one sweep later).
        """
        from scipy.spatial.transform import Rotation

        s = self.sensor
        alpha = np.arange(s.azimuths) / s.azimuths  # (A,) fraction of the sweep
        delta = Rotation.from_matrix(T_start[:3, :3].T @ T_end[:3, :3]).as_rotvec()
        T_col = np.tile(np.eye(4), (s.azimuths, 1, 1))
        turn = Rotation.from_rotvec(alpha[:, None] * delta).as_matrix()
        T_col[:, :3, :3] = T_start[:3, :3] @ turn
        T_col[:, :3, 3] = T_start[:3, 3] + alpha[:, None] * (T_end[:3, 3] - T_start[:3, 3])
        with _one_blas_thread():
            pts, col = self._scan(T_col, rng, movers, compensate)
        return pts, (alpha[col] / s.rate_hz).astype(np.float32)

    def _scan(self, T_col: F64, rng: np.random.Generator,
              movers: tuple[F64, NDArray[np.int64]] | None,
              compensate: bool) -> tuple[F32, NDArray[np.int64]]:
        """Fire every ray, column a from pose ``T_col[a]`` (one pose: all columns); the kept
        points (N, 4) (lidar frame at the firing, or at ``T_col[0]`` with ``compensate``) and
        the azimuth column of each. With ``threads`` > 1 the returns' random numbers are drawn
        on a second thread while this one reads the relief, and the returns shaped by all."""
        g, e = self._beam, self.sensor.effects
        phase = rng.uniform(0.0, np.deg2rad(self.sensor.azimuth_step_deg))
        c, si = np.cos(phase), np.sin(phase)
        Rz = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]], np.float32)
        R = T_col[:, :3, :3] @ Rz.astype(np.float64)  # (A or 1, 3, 3): lidar at the firing
        noise = None
        if e.angle_jitter_deg > 0.0:  # isotropic: the same in any frame
            noise = rng.standard_normal((len(g.column_free), 3), dtype=np.float32)
        rays = g.world_rays(R, T_col[:, :3, 3] - self.origin, noise=noise,
                            sigma_rad=float(np.float32(np.deg2rad(e.angle_jitter_deg))))
        orig_w, dirs_w = rays[:, :3], rays[:, 3:]
        hits = self._cast_rays(rays)
        if movers is not None and len(movers[1]):
            hits = _nearer(hits, _cast_movers(self._o3d, movers[0] - self.origin, movers[1],
                                              orig_w, dirs_w, self.threads))
        t, cos_set = hits.t, np.full(len(hits.t), -1.0, np.float32)
        if e.vegetation_free_path_m > 0.0:
            t = t.copy()
            self._foliage(t, cos_set, hits, orig_w, dirs_w, rng)
        draw = (int(rng.integers(2**31)), t, hits.material, float(self._settings[0]))
        drawn = (_helpers(self.threads - 1).submit(draw_uniforms, *draw) if self.threads > 1
                 else None)
        if compensate and len(T_col) > 1:  # into the frame at the sweep's start
            T_rel = np.linalg.solve(T_col[0], T_col)  # (A, 4, 4) T_start_column
            out = g.world_rays(T_rel[:, :3, :3] @ Rz.astype(np.float64), T_rel[:, :3, 3],
                               stored=True)
        else:
            out = g.world_rays(Rz[None].astype(np.float64), np.zeros((1, 3)), stored=True)
        height = self._relief(t, hits.material, rays)
        u = drawn.result() if drawn is not None else draw_uniforms(*draw)
        kept, points = np.empty(len(t), np.bool_), np.empty((len(t), 4), np.float32)
        self._in_parts(shape_returns, u, t, hits.normal, hits.material, cos_set, height,
                       dirs_w, g.range_bias_free, out[:, 3:], out[:, :3], REFLECTANCE,
                       self._settings, points, kept)
        points, free = kept_rows(points, kept)
        return points, g.column_free[free]

    def _relief(self, t: F32, material: NDArray[np.uint8], rays: F32) -> F32:
        """(M,) the height [m] of the surfaces' relief (fixed in the world) at the hits of
        ``rays`` (M, 6) at ranges ``t`` (M,) on ``material`` (M,): 0 where none."""
        height = np.zeros(len(t), np.float32)
        relief_m = self.sensor.effects.surface_relief_m
        if relief_m > 0.0:
            rough, hit_w = rough_hits(rays, t, material, RELIEF)
            lay_relief(height, rough, self._bumps(hit_w, self.origin), material, RELIEF,
                       relief_m)
        return height

    def _in_parts(self, kernel: Any, *args: Any) -> None:
        """``kernel(part, parts, *args)`` for every part of ``threads``, on as many threads."""
        parts = self.threads
        running = [_helpers(parts - 1).submit(kernel, p, parts, *args) for p in range(1, parts)]
        kernel(0, parts, *args)
        for job in running:
            job.result()

    def _cast(self, origins: F32, dirs: F32) -> Hits:
        """Cast rays (M, 3) + (M, 3) against the world."""
        rays = np.empty((len(dirs), 6), np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = dirs
        return self._cast_rays(rays)

    def _cast_rays(self, rays: F32) -> Hits:
        """Cast rays (M, 6) (origin, direction) against the world."""
        t, normal, prim = _exact_cast(self.scene, self._vertices, self._triangles, rays,
                                      self.threads)
        mat = np.zeros(len(t), np.uint8)
        ok = np.isfinite(t)
        mat[ok] = self.materials[prim[ok]]
        return Hits(t, normal, mat)

    def _foliage(self, t: F32, cos_set: F32, hits: Hits, orig_w: F32, dirs_w: F32,
                 rng: np.random.Generator) -> None:
        """Rays whose first hit is foliage enter it: each travels an exponential depth (mean
        free path) and returns from there unless it leaves the crown first (then the next
        surface answers; foliage hit from outside only at its face). Updates the ranges ``t``
        and sets the incidence of a return from inside (``cos_set``: a random leaf's, cos
        uniform) in place."""
        veg = np.flatnonzero(hits.material == Material.VEGETATION)
        if not len(veg):
            return
        depth = rng.exponential(self.sensor.effects.vegetation_free_path_m,
                                len(veg)).astype(np.float32)
        leaf = rng.uniform(0.0, 1.0, len(veg)).astype(np.float32)
        start = t[veg] + VEGETATION_STEP_M
        inner = self._cast(orig_w[veg] + dirs_w[veg] * start[:, None], dirs_w[veg])
        inside = depth < inner.t
        t[veg[inside]] += depth[inside]
        cos_set[veg[inside]] = leaf[inside]
        out = ~inside
        exits = out & (inner.material == Material.VEGETATION)
        solid = out & ~exits
        t[veg[solid]] = start[solid] + inner.t[solid]
        cos_set[veg[solid]] = np.abs(_dot(inner.normal[solid], dirs_w[veg[solid]]))
        if exits.any():
            far = start[exits] + inner.t[exits] + VEGETATION_STEP_M
            r = veg[exits]
            behind = self._cast(orig_w[r] + dirs_w[r] * far[:, None], dirs_w[r])
            t[r] = far + behind.t
            cos_set[r] = np.abs(_dot(behind.normal, dirs_w[r]))

    def distance_to_mesh(self, points_world: F64) -> F64:
        """(N,) unsigned distance [m] from world points (N, 3) to the mesh."""
        q = self._o3d.core.Tensor((points_world - self.origin).astype(np.float32))  # type: ignore[call-overload]
        return self.scene.compute_distance(q).numpy().astype(np.float64)


class Relief:
    """The waves of a unit-variance 3-D noise fixed in the world: a sum of plane waves of
    0.3-2 m wavelength (the relief a mesh leaves out: recessed windows and sills, car bodies,
    clods, bark). ``k`` (W, 3) wave vectors [rad/m], ``phase`` (W,) [rad]."""

    def __init__(self, rng: np.random.Generator, waves: int = 8) -> None:
        lam = np.exp(rng.uniform(np.log(0.3), np.log(2.0), waves))
        k = rng.standard_normal((waves, 3))
        self.k = (2 * np.pi / lam[:, None] * k / np.linalg.norm(k, axis=1, keepdims=True)
                  ).astype(np.float32)
        self.phase = rng.uniform(0.0, 2 * np.pi, waves).astype(np.float32)

        self._k_t = np.ascontiguousarray(self.k.T)

    def __call__(self, p: F32, origin: F64) -> F32:
        """(N,) the noise at points (N, 3) [m] given relative to ``origin`` (3,) [m] (the
        phases are moved there in float64: the field stays fixed in the world to the mm)."""
        phase = ((self.k.astype(np.float64) @ origin + self.phase) % (2 * np.pi))
        arg = p @ self._k_t
        arg += phase.astype(np.float32)
        np.sin(arg, out=arg)
        return row_sums(arg) * np.float32(np.sqrt(2.0 / len(self.phase)))


class _BeamGeometry:
    """The rays of one sensor unit (its calibration errors drawn once from
    ``effects.unit_seed``), fixed for every scan: the rays the carrier leaves free (``active``,
    beam-major indices; ``column_free`` the azimuth column of each), their reported and true
    directions (M, 3) in the lidar frame at phase 0, their laser's height (M,) and range offset
    (M,). A scan only turns them (``world_rays``)."""

    def __init__(self, sensor: SensorModel) -> None:
        e = sensor.effects
        unit = np.random.default_rng([e.unit_seed, 71])
        el_err = unit.standard_normal(sensor.beams) * e.laser_elevation_error_deg
        bias = unit.standard_normal(sensor.beams) * e.laser_range_bias_m
        az_err = unit.standard_normal(sensor.beams) * e.laser_azimuth_error_deg
        true_el = np.asarray(sensor.elevations_deg) - e.elevation_error_deg - el_err
        self.beams, self.azimuths = sensor.beams, sensor.azimuths
        self.active = np.flatnonzero(~sensor.hidden_rays())
        self.column_free = self.active % self.azimuths
        dirs_true = sensor.ray_directions(elevations_deg=true_el, azimuth_offsets_deg=-az_err)
        self._free = {False: dirs_true[self.active], True: sensor.ray_directions()[self.active]}
        self.heights = sensor.laser_heights().astype(np.float32)
        self.lifted = bool(self.heights.any())
        self.height_free = self.heights[self.active // self.azimuths]
        self.range_bias_free = bias.astype(np.float32)[self.active // self.azimuths]

    def world_rays(self, R: F64, t: F64, stored: bool = False, noise: F32 | None = None,
                   sigma_rad: float = 0.0) -> F32:
        """(M, 6) float32 origins and directions of the free rays (true ones, or as the sensor
        reports them with ``stored``) fired from column poses (``R`` (A, 3, 3), ``t`` (A, 3);
        or one pose (1, ...) for all columns); ``noise`` (M, 3) x ``sigma_rad``: the firings'
        angle jitter added to the directions (an isotropic perturbation; its part along the ray
        changes the length by a factor 1 + O(sigma^2), negligible at the jitters of a LiDAR)."""
        free = self._free[stored]
        rays = np.empty((len(free), 6), np.float32)
        turn_rays(free, self.column_free, R.astype(np.float32), t.astype(np.float32),
                  self.height_free, len(R) == 1 or self.lifted,
                  _NO_NOISE if noise is None else noise, float(sigma_rad), rays)
        return rays


@functools.cache
def _helpers(threads: int) -> ThreadPoolExecutor:
    """``threads`` threads that share a scan's work with the one casting it (kept for the
    process's life, idle between scans)."""
    return ThreadPoolExecutor(threads, thread_name_prefix="raycast")


@functools.cache
def _blas_controller() -> Any:
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def _one_blas_thread() -> Any:
    """A context in which BLAS runs on one thread: the scan's products are (M, 3) by (3, k),
    which OpenBLAS's threads slow down by 10-50 times when the cores are busy (and the
    simulator runs in processes of its own anyway)."""
    return _blas_controller().limit(limits=1, user_api="blas")


def _dot(a: F32, b: F32) -> F32:
    """(M,) row-wise dot products of (M, 3) arrays."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _cast_movers(o3d: object, vertices: F64, triangles: NDArray[np.int64], origins: F32,
                 dirs: F32, threads: int) -> Hits:
    """Cast the rays that pass within the bounding sphere of the movers' mesh against it
    (vehicles); the others miss."""
    centre = vertices.mean(axis=0)
    radius = float(np.linalg.norm(vertices - centre, axis=1).max())
    rel = centre.astype(np.float32) - origins
    along = np.einsum("ij,ij->i", rel, dirs)
    near = np.flatnonzero((along > 0) & (np.einsum("ij,ij->i", rel, rel) - along**2
                                         < radius**2))
    t = np.full(len(dirs), np.inf, np.float32)
    normal = np.zeros((len(dirs), 3), np.float32)
    if len(near):
        hit = _cast_mesh(o3d, vertices, triangles, origins[near], dirs[near], Material.VEHICLE,
                         threads)
        t[near], normal[near] = hit.t, hit.normal
    return Hits(t, normal, np.full(len(dirs), Material.VEHICLE, np.uint8))


def _cast_mesh(o3d: object, vertices: F64, triangles: NDArray[np.int64], origins: F32,
               dirs: F32, material: Material, threads: int) -> Hits:
    """Cast rays against a small mesh of one material (the movers of a scan) on ``threads``."""
    vertices_f32 = vertices.astype(np.float32)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    scene = o3d.t.geometry.RaycastingScene()  # type: ignore[attr-defined]
    scene.add_triangles(o3d.core.Tensor(vertices_f32),  # type: ignore[attr-defined]
                        o3d.core.Tensor(triangles.astype(np.uint32)))  # type: ignore[attr-defined]
    rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
    t, normal, _ = _exact_cast(scene, vertices_f32, triangles, rays, threads)
    return Hits(t, normal, np.full(len(t), material, np.uint8))


def _exact_cast(scene: Any, vertices: F32, triangles: NDArray[np.int64], rays: F32,
                threads: int) -> tuple[F32, F32, NDArray[np.uint32]]:
    """Cast ``rays`` (M, 6) against ``scene`` (built from ``vertices`` (V, 3) float32 and
    ``triangles`` (T, 3)): each ray's range (inf: none), unit normal and triangle, the range and
    normal recomputed from the triangle (``hits_kernel``: Embree's own differ between CPUs in
    their last bits)."""
    import open3d as o3d

    hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=threads)
    t = np.array(hit["t_hit"].numpy(), np.float32)
    normal = np.array(hit["primitive_normals"].numpy(), np.float32)
    prim = hit["primitive_ids"].numpy()
    exact_hits(vertices, triangles, rays, prim, t, normal)
    return t, normal, prim


def _nearer(a: Hits, b: Hits) -> Hits:
    """Per ray, the nearer of two casts."""
    closer = b.t < a.t
    if not closer.any():
        return a
    return Hits(np.where(closer, b.t, a.t), np.where(closer[:, None], b.normal, a.normal),
                np.where(closer, b.material, a.material))


def _settings(e: SensorEffects, min_range_m: float, max_range_m: float) -> NDArray[np.float64]:
    """The numbers ``shape_returns`` takes (its docstring), from the effects."""
    log_c = np.log(e.detection_range_m**2 / 0.1) if e.detection_range_m > 0.0 else np.nan
    return np.array([e.ground_cover_m if e.vegetation_free_path_m > 0.0 else 0.0,
                     e.vegetation_free_path_m, log_c,
                     e.incidence_exponent, e.detection_spread, e.dropout,
                     e.range_noise_m**2, e.range_noise_growth_m / 100.0,
                     e.beam_divergence_mrad * 1e-3 / np.sqrt(12.0), min_range_m, max_range_m])
