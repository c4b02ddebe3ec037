"""Ray casting a sensor model against a world mesh (open3d RaycastingScene, Embree).

``scan``: all rays of a scan (beams x azimuths) are cast at once from the frame's pose: the
scan is instantaneous (no motion distortion within a scan). ``sweep``: the azimuth columns are
fired one after the other over the sweep, each from the pose at its own time (linear in
translation, slerp in rotation between the sweep's start and end poses), so the points carry
the motion distortion of a real spinning sensor, and each gets its time. Each return gets
Gaussian range noise, random dropouts, a random azimuth phase per scan (as a free-running
spinning sensor has), and an intensity = |cos(incidence angle)|.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.sim.sensors import SensorModel

F64 = NDArray[np.float64]


class Raycaster:
    """Casts scans of ``sensor`` against one mesh. Build once per world, call ``scan`` per frame.

    The mesh is shifted to a local origin so that float32 ray casting keeps mm precision
    far from the world origin.
    """

    def __init__(self, vertices: F64, triangles: NDArray[np.int64], sensor: SensorModel) -> None:
        import open3d as o3d

        self.sensor = sensor
        self.origin = np.round(vertices.mean(axis=0)) if len(vertices) else np.zeros(3)
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor((vertices - self.origin).astype(np.float32)),  # type: ignore[call-overload]
            o3d.core.Tensor(triangles.astype(np.uint32)),  # type: ignore[call-overload]
        )
        self._dirs = sensor.ray_directions()
        self._o3d = o3d

    def scan(self, T_world_lidar: F64, rng: np.random.Generator) -> NDArray[np.float32]:
        """(N, 4) float32 points [m] in the lidar frame + intensity in [0, 1]."""
        s = self.sensor
        phase = rng.uniform(0.0, np.deg2rad(s.azimuth_step_deg))
        c, si = np.cos(phase), np.sin(phase)
        Rz = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
        dirs_world = self._dirs @ (T_world_lidar[:3, :3] @ Rz).T.astype(np.float32)
        rays = np.empty((len(dirs_world), 6), np.float32)
        rays[:, :3] = (T_world_lidar[:3, 3] - self.origin).astype(np.float32)
        rays[:, 3:] = dirs_world
        return self._returns(rays, dirs_world, Rz, rng)[0]

    def sweep(self, T_start: F64, T_end: F64,
              rng: np.random.Generator) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """A motion-distorted scan: ((N, 4) float32 points in the lidar frame at each point's
        firing time + intensity, (N,) float32 firing time [s] after the sweep's start).

        Column a of the A azimuth columns fires at a / A of the sweep (1 / rate_hz s), from the
        pose interpolated between ``T_start`` (the stamp) and ``T_end`` (one sweep later).
        """
        from scipy.spatial.transform import Rotation

        s = self.sensor
        phase = rng.uniform(0.0, np.deg2rad(s.azimuth_step_deg))
        c, si = np.cos(phase), np.sin(phase)
        Rz = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
        alpha = np.arange(s.azimuths) / s.azimuths  # (A,) fraction of the sweep
        delta = Rotation.from_matrix(T_start[:3, :3].T @ T_end[:3, :3]).as_rotvec()
        R_col = T_start[:3, :3] @ Rotation.from_rotvec(alpha[:, None] * delta).as_matrix()
        p_col = T_start[:3, 3] + alpha[:, None] * (T_end[:3, 3] - T_start[:3, 3])
        col = np.arange(len(self._dirs)) % s.azimuths  # beam-major rows: column of each ray
        local = self._dirs @ Rz.T.astype(np.float32)
        dirs_world = np.einsum("nij,nj->ni", R_col[col], local).astype(np.float32)
        rays = np.empty((len(dirs_world), 6), np.float32)
        rays[:, :3] = (p_col[col] - self.origin).astype(np.float32)
        rays[:, 3:] = dirs_world
        pts, idx = self._returns(rays, dirs_world, Rz, rng)
        return pts, (alpha[col[idx]] / s.rate_hz).astype(np.float32)

    def _returns(self, rays: NDArray[np.float32], dirs_world: NDArray[np.float32],
                 Rz: F64, rng: np.random.Generator) -> tuple[NDArray[np.float32], NDArray]:
        """Cast ``rays`` (M, 6); the kept returns (N, 4) in the lidar frame and their ray
        indices (N,)."""
        s = self.sensor
        hit = self.scene.cast_rays(self._o3d.core.Tensor.from_numpy(rays))
        t_hit = hit["t_hit"].numpy()
        r = t_hit + rng.standard_normal(len(t_hit), dtype=np.float32) * np.float32(s.range_noise_m)
        keep = (r >= s.min_range_m) & (r <= s.max_range_m)  # misses are inf
        keep &= rng.random(len(t_hit), dtype=np.float32) >= s.dropout
        idx = np.flatnonzero(keep)
        out = np.empty((len(idx), 4), np.float32)
        out[:, :3] = (self._dirs[idx] @ Rz.T.astype(np.float32)) * r[idx, None]
        n = hit["primitive_normals"].numpy()[idx]
        out[:, 3] = np.abs(np.einsum("ij,ij->i", n, dirs_world[idx]))
        return out, idx

    def distance_to_mesh(self, points_world: F64) -> F64:
        """(N,) unsigned distance [m] from world points (N, 3) to the mesh."""
        q = self._o3d.core.Tensor((points_world - self.origin).astype(np.float32))  # type: ignore[call-overload]
        return self.scene.compute_distance(q).numpy().astype(np.float64)
