"""The compiled voxel grid (pipeline/odometry/voxel_kernel.py) gives the numpy code it replaced
to the last bit: keys, voxel order and centroids, whose sums follow numpy's pairwise order. A
last-bit change would move every NDT run (odometry is chaotic in its input)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers.models import kitti_scan
from numpy.typing import NDArray

from pipeline.odometry.common import voxel_downsample, voxel_keys


def numpy_downsample(points: NDArray[np.floating], voxel_m: float) -> NDArray[np.float64]:
    """``voxel_downsample`` as numpy computed it before the kernel (main@6be50a0)."""
    pts = np.asarray(points, dtype=np.float64)
    if voxel_m <= 0 or len(pts) == 0:
        return pts.copy()
    keys = voxel_keys(pts, voxel_m)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.concatenate([[True], sorted_keys[1:] != sorted_keys[:-1]]))
    sums = np.add.reduceat(pts[order], starts, axis=0)
    counts = np.diff(np.append(starts, len(pts)))
    return sums / counts[:, None]


def same_bits(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("voxel_m", [0.05, 0.5, 1.0, 3.7, 40.0])
def test_random_clouds_give_the_numpy_bits(dtype: type, voxel_m: float) -> None:
    """Voxels of 1 to thousands of points (every branch of the pairwise sum: < 8, 8-128 and
    halves above), points on voxel faces, negative coordinates, keys clipped far away."""
    rng = np.random.default_rng(int(voxel_m * 100))
    near = rng.normal(0.0, 3.0, (20000, 3))
    far = rng.uniform(-3e6, 3e6, (50, 3))  # beyond 2**20 voxels: clipped keys
    faces = np.round(rng.normal(0.0, 10.0, (2000, 3)) / voxel_m) * voxel_m
    cloud = np.concatenate([near, far, faces, -faces]).astype(dtype)
    for points in (cloud, cloud[:7], cloud[:1], cloud[:300]):
        assert same_bits(voxel_downsample(points, voxel_m), numpy_downsample(points, voxel_m))


def test_a_strided_view_and_the_edge_cases() -> None:
    rng = np.random.default_rng(3)
    scan = rng.normal(0.0, 20.0, (5000, 4)).astype(np.float32)
    assert same_bits(voxel_downsample(scan[:, :3], 1.0), numpy_downsample(scan[:, :3], 1.0))
    for voxel_m in (0.0, -1.0):
        assert same_bits(voxel_downsample(scan[:, :3], voxel_m),
                         numpy_downsample(scan[:, :3], voxel_m))
    empty = np.zeros((0, 3), np.float32)
    assert same_bits(voxel_downsample(empty, 1.0), numpy_downsample(empty, 1.0))


def test_kitti_scans_give_the_numpy_bits(kitti_root: Path) -> None:
    """Real HDL-64E scans at the ndt adapter's source voxel (1 m) and around it."""
    for seq, frame in (("01", 0), ("04", 5), ("06", 9), ("10", 3)):
        xyz = kitti_scan(kitti_root, seq, frame)[:, :3]
        for voxel_m in (0.3, 1.0, 2.0):
            assert same_bits(voxel_downsample(xyz, voxel_m), numpy_downsample(xyz, voxel_m))
