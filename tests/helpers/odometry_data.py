"""Test and bench sequences (and test helpers) for the odometry adapters.

- ``write_synthetic_sequence``: an HDL-32E-like sensor (32 beams, -30.67..+10.67 deg, 1800
  azimuth steps, ~50k points a scan) ray-cast with open3d into a walled yard with boxes of random
  sizes, driven along a gentle S-curve; 1 cm range noise. Ground truth = the driven poses.
- ``write_kitti_sequence``: real KITTI frames (kitti_mini) with T_world_lidar = inv(Tr) P Tr.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import inv_se3, rot_z
from pipeline.sequence import Scan, SequenceInfo, SequenceReader, SequenceWriter

F64 = NDArray[np.float64]


def hdl32_directions(azimuth_steps: int = 1800) -> F64:
    """Unit ray directions (32 * azimuth_steps, 3) of an HDL-32E in its own frame."""
    elev = np.deg2rad(np.linspace(-30.67, 10.67, 32))
    az = np.linspace(-np.pi, np.pi, azimuth_steps, endpoint=False)
    el, a = np.meshgrid(elev, az, indexing="ij")
    return np.stack([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)], -1).reshape(-1, 3)


def yard_scene(seed: int = 0, length_m: float = 120.0, width_m: float = 24.0):
    """open3d RaycastingScene: ground, four walls, 60 boxes of random size and yaw."""
    import open3d as o3d

    rng = np.random.default_rng(seed)
    mesh = o3d.geometry.TriangleMesh()

    def box(sx: float, sy: float, sz: float, x: float, y: float, z: float,
            yaw: float = 0.0) -> None:
        b = o3d.geometry.TriangleMesh.create_box(sx, sy, sz)
        b.translate((-sx / 2, -sy / 2, 0.0))
        b.rotate(rot_z(yaw), center=(0.0, 0.0, 0.0))
        b.translate((x, y, z))
        mesh.__iadd__(b)

    box(length_m + 40, width_m + 40, 0.2, length_m / 2, 0.0, -2.0)  # ground 2 m below the sensor
    for sign in (-1, 1):
        box(length_m + 20, 0.5, 6.0, length_m / 2, sign * width_m / 2, -1.8)
        box(0.5, width_m, 6.0, length_m / 2 + sign * (length_m / 2 + 10), 0.0, -1.8)
    for _ in range(60):
        x = rng.uniform(-5, length_m + 5)
        y = rng.choice([-1, 1]) * rng.uniform(4.0, width_m / 2 - 1)
        box(*rng.uniform([0.5, 0.5, 0.5], [4.0, 4.0, 5.0]), x, y, -1.8, rng.uniform(0, np.pi))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return scene


def s_curve_poses(n_frames: int, step_m: float) -> F64:
    """(n_frames, 4, 4) T_world_lidar along x with a lateral S-curve and a little pitch."""
    s = np.arange(n_frames) * step_m
    y = 1.5 * np.sin(s / 15.0)
    yaw = np.arctan(1.5 / 15.0 * np.cos(s / 15.0))
    T = np.tile(np.eye(4), (n_frames, 1, 1))
    for i in range(n_frames):
        pitch = 0.02 * np.sin(s[i] / 7.0)
        c, s_ = np.cos(pitch), np.sin(pitch)
        Ry = np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
        T[i, :3, :3] = rot_z(yaw[i]) @ Ry
        T[i, :3, 3] = (s[i], y[i], 0.0)
    return T


def raycast(scene, T_world_lidar: F64, dirs: F64, rng: np.random.Generator,
            max_range_m: float = 80.0) -> NDArray[np.float32]:
    """Points (N, 3) float32 in the sensor frame of the rays ``dirs`` hitting ``scene``."""
    import open3d as o3d

    d_world = dirs @ T_world_lidar[:3, :3].T
    rays = np.concatenate([np.broadcast_to(T_world_lidar[:3, 3], d_world.shape), d_world], 1)
    hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    ok = np.isfinite(hit) & (hit < max_range_m) & (hit > 0.5)
    r = hit[ok] + rng.normal(0, 0.01, ok.sum())
    return (dirs[ok] * r[:, None]).astype(np.float32)


def write_synthetic_sequence(path: Path, n_frames: int = 20, step_m: float = 0.8,
                             seed: int = 0, azimuth_steps: int = 1800) -> Path:
    """A ray-cast HDL-32E sequence at 10 Hz (``step_m`` per frame) with ground truth."""
    rng = np.random.default_rng(seed)
    scene = yard_scene(seed)
    dirs = hdl32_directions(azimuth_steps)
    info = SequenceInfo(name=path.stem, sensor="HDL-32E (simulated)", source="test ray-cast yard")
    with SequenceWriter(path, info) as w:
        for i, T in enumerate(s_curve_poses(n_frames, step_m)):
            w.add(1_000_000_000 + i * 100_000_000, raycast(scene, T, dirs, rng), T)
    return path


def read_kitti_calib_tr(calib_txt: Path) -> F64:
    """Tr (velodyne -> camera 0) of a KITTI calib.txt as a (4, 4) matrix."""
    for line in calib_txt.read_text().splitlines():
        if line.startswith("Tr:"):
            T = np.eye(4)
            T[:3, :] = np.array(line.split()[1:], float).reshape(3, 4)
            return T
    raise ValueError(f"{calib_txt}: no Tr line")


def kitti_lidar_poses(kitti_root: Path, seq: str) -> F64:
    """(N, 4, 4) T_world_lidar = inv(Tr) P Tr of a KITTI sequence's ground truth."""
    Tr = read_kitti_calib_tr(kitti_root / "sequences" / seq / "calib.txt")
    P = np.loadtxt(kitti_root / "poses" / f"{seq}.txt").reshape(-1, 3, 4)
    T = np.tile(np.eye(4), (len(P), 1, 1))
    T[:, :3, :] = P
    return np.linalg.inv(Tr) @ T @ Tr


def write_kitti_sequence(path: Path, kitti_root: Path, seq: str = "04", n_frames: int = 10) -> Path:
    """Frames 0..n_frames-1 of a KITTI sequence as a sequence MCAP with ground truth."""
    base = kitti_root / "sequences" / seq
    times = np.loadtxt(base / "times.txt")
    poses = kitti_lidar_poses(kitti_root, seq)
    info = SequenceInfo(name=path.stem, sensor="HDL-64E", source=f"KITTI odometry {seq}")
    with SequenceWriter(path, info) as w:
        for i in range(n_frames):
            pts = np.fromfile(base / "velodyne" / f"{i:06d}.bin", np.float32).reshape(-1, 4)
            w.add(round(float(times[i]) * 1e9) + 1, pts, poses[i])
    return path


SCRIPTS = Path(__file__).resolve().parents[1] / "odometry" / "scripts"


def command_options(fmt: str = "kitti") -> dict[str, Any]:
    """Options of the ``command`` adapter driving the real scan-to-scan GICP test script."""
    return {
        "command": ["{python}", str(SCRIPTS / "s2s_gicp.py"), "{sequence}", "{schedule}", "{out}",
                    fmt],
        "space": str(SCRIPTS / "s2s_gicp_space.yaml"),
        "format": fmt,
    }


ADAPTER_OPTIONS: dict[str, dict[str, Any]] = {"command": command_options()}


def make_adapter(name: str) -> Any:
    """Adapter ``name`` with the options the tests use."""
    from pipeline.odometry import get_adapter

    return get_adapter(name, **ADAPTER_OPTIONS.get(name, {}))


class Seq:
    """A sequence MCAP loaded once: path, scans, ground truth relative to frame 0."""

    def __init__(self, path: Path) -> None:
        self.path = path
        with SequenceReader(path) as r:
            self.scans: list[Scan] = list(r)
            gt = r.ground_truth()
        assert gt is not None
        self.gt = inv_se3(gt[0]) @ gt

    def __len__(self) -> int:
        return len(self.scans)


def final_errors(est: F64, gt: F64) -> tuple[float, float]:
    """(translation [m], rotation [deg]) error of the last pose, both relative to frame 0."""
    E = inv_se3(est[-1]) @ gt[-1]
    angle = np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(E[:3, 3])), float(angle)
