"""The NDT voxel classification histogram (pipeline/descriptors/ndt_histogram.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.descriptors.ndt_histogram import (
    _DENSE_MAX_CELLS,
    NdtHistogram,
    _crop,
    _moments,
    _moments_kernel,
    bin_names,
    classify,
    describe,
    sym3_eigvals,
    voxel_moments,
)
from pipeline.errors import ConfigError


def kitti(kitti_root: Path, seq: str, frame: int) -> np.ndarray:
    return np.fromfile(
        kitti_root / "sequences" / seq / "velodyne" / f"{frame:06d}.bin", np.float32
    ).reshape(-1, 4)


def rot_z(deg: float) -> np.ndarray:
    t = np.deg2rad(deg)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])


def rotated(points: np.ndarray, deg: float) -> np.ndarray:
    out = points.copy()
    out[:, :3] = (points[:, :3].astype(np.float64) @ rot_z(deg).T).astype(np.float32)
    return out


def test_yaw_invariance_real_scan(kitti_root: Path) -> None:
    """Classes, tilts, ratios and ranges are yaw invariant; only the axis-aligned voxel grid
    moves with the scan. Rotations by multiples of 90 deg map the grid onto itself: equal
    histograms. Other angles re-cut the voxels: the L1 distance (of histograms that sum to 1)
    stays <= 0.15 -- about the change between two consecutive frames (0.11 measured) and a
    third of the distance to a scan of another sequence (0.43 measured), asserted below."""
    scan = kitti(kitti_root, "04", 0)
    h = describe(scan)
    assert h.shape == (90,) and abs(h.sum() - 1.0) < 1e-5
    for deg in (90, 180, 270):
        np.testing.assert_allclose(describe(rotated(scan, deg)), h, atol=2e-3)
    dists = [np.abs(describe(rotated(scan, deg)) - h).sum() for deg in (17, 45, 137, 301)]
    assert max(dists) <= 0.15, dists
    other = np.abs(describe(kitti(kitti_root, "01", 0)) - h).sum()
    assert other > 2.5 * max(dists)
    # the class totals (summed over range) move even less
    tot = h.reshape(10, 3, 3).sum(0)
    for deg in (17, 137):
        assert np.abs(describe(rotated(scan, deg)).reshape(10, 3, 3).sum(0) - tot).sum() <= 0.1


def grid_plane(
    normal: np.ndarray,
    centre: np.ndarray,
    size: float,
    rng: np.random.Generator,
    n: int = 4000,
    noise: float = 0.01,
) -> np.ndarray:
    normal = normal / np.linalg.norm(normal)
    a = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    uv = rng.uniform(-size / 2, size / 2, (n, 2))
    return centre + uv[:, :1] * a + uv[:, 1:] * b + rng.normal(0, noise, (n, 1)) * normal


def classes_of(points: np.ndarray, config: NdtHistogram | None = None) -> np.ndarray:
    """(3, 3) class x sub-class fractions of a point set."""
    h = describe(points.astype(np.float32), config or NdtHistogram())
    return h.reshape(10, 3, 3).sum(0)


@pytest.mark.parametrize(("normal", "sub"), [((0, 0, 1), 0), ((1, 0, 1), 1), ((1, 1, 0.1), 2)])
def test_plane_gives_planar_voxels_of_its_tilt(
    rng: np.random.Generator, normal: tuple, sub: int
) -> None:
    pts = grid_plane(np.array(normal, float), np.array([10.3, 4.1, -1.2]), 6.0, rng, n=20000)
    c = classes_of(pts)
    # planar voxels of the right sub-class (horizontal / slope / vertical plane) dominate; the
    # rest are slivers where the grid cuts the plane's edge or a voxel corner (thin: linear)
    assert np.unravel_index(np.argmax(c), c.shape) == (1, sub) and c[1, sub] > 0.5, c
    assert c[1].sum() == c[1, sub]


@pytest.mark.parametrize(("direction", "sub"), [((0, 0, 1), 2), ((1, 0.3, 0), 0), ((1, 0, 1), 1)])
def test_pole_gives_linear_voxels_of_its_tilt(
    rng: np.random.Generator, direction: tuple, sub: int
) -> None:
    d = np.array(direction, float) / np.linalg.norm(direction)
    t = rng.uniform(-3, 3, (6000, 1))
    pts = np.array([-7.2, 5.5, 0.4]) + t * d + rng.normal(0, 0.01, (6000, 3))
    c = classes_of(pts)
    assert c[0, sub] > 0.85, c


def test_blob_gives_spherical_isotropic(rng: np.random.Generator) -> None:
    pts = rng.uniform(0, 4, (40000, 3)) + np.array([3.0, -12.0, -2.0])  # a filled cube of voxels
    c = classes_of(pts)
    assert c[2, 2] > 0.9, c


def test_range_bins_and_layout(rng: np.random.Generator) -> None:
    pts = grid_plane(np.array([0, 0, 1.0]), np.array([10.5, 0.0, -1.5]), 1.8, rng, n=3000)
    h = describe(pts.astype(np.float32))
    names = bin_names()
    assert len(names) == 90 and names[int(np.argmax(h))] == "r03_planar_horizontal_plane"
    far = pts + np.array([40.0, 0, 0])  # beyond 30 m: cropped, empty histogram
    assert not describe(far.astype(np.float32)).any()
    raw = describe(pts.astype(np.float32), NdtHistogram(normalize=False))
    assert raw.sum() == raw.max() and raw.sum() >= 4  # counts of voxels


def test_moments_and_eigenvalues(rng: np.random.Generator) -> None:
    pts = rng.normal(0, 1, (5000, 3)).astype(np.float32) * np.float32(3.0)
    counts, mean, cov = voxel_moments(tuple(np.ascontiguousarray(pts.T)), 1.0, 5)
    keys = np.floor(pts).astype(int)
    _, inv, cnt = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    big = np.flatnonzero(cnt >= 5)
    assert len(counts) == len(big) and counts.sum() == cnt[big].sum()
    g = big[int(np.argmax(cnt[big]))]
    member = pts[inv.reshape(-1) == g].astype(np.float64)
    j = int(np.argmax(counts))
    np.testing.assert_allclose(mean[j], member.mean(0), atol=1e-6)
    np.testing.assert_allclose(cov[j], np.cov(member.T, bias=True), atol=1e-6)
    lam = sym3_eigvals(cov)
    np.testing.assert_allclose(lam, np.linalg.eigvalsh(cov)[:, ::-1], atol=1e-12)
    cls, sub = classify(cov, 0.1)
    assert cls.shape == sub.shape == (len(cov),) and set(np.unique(sub)) <= {0, 1, 2}


def assert_same_moments(points: np.ndarray, config: NdtHistogram) -> None:
    """``describe``'s moments equal the numpy reference ``voxel_moments(_crop(points))``."""
    ref = voxel_moments(_crop(points, config.max_range_m), config.voxel_size_m, config.min_points)
    got = _moments(points, config)
    assert len(ref[0]) > 0
    np.testing.assert_array_equal(got[0], ref[0])  # the same voxels, in the same order
    np.testing.assert_allclose(got[1], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[2], ref[2], rtol=0, atol=1e-9)


def test_numba_kernel_matches_numpy_reference(
    kitti_root: Path, rng: np.random.Generator
) -> None:
    """The numba kernel (the default path) and the numpy reference agree on real scans, on
    float64 input, with NaN and far points, and for other voxel sizes; a bounding box of more
    than _DENSE_MAX_CELLS cells is refused by the kernel and falls back to numpy."""
    kernel = _moments_kernel()
    assert kernel is not None
    config = NdtHistogram()
    for seq, frame in (("04", 0), ("01", 7)):
        scan = kitti(kitti_root, seq, frame)
        assert_same_moments(scan, config)
        assert_same_moments(scan[:, :3].astype(np.float64), NdtHistogram(voxel_size_m=0.5))
    messy = kitti(kitti_root, "04", 3).copy()
    messy[::97, 1] = np.nan
    messy[::89, :3] *= 40.0  # beyond 30 m
    assert_same_moments(messy, config)
    fine = NdtHistogram(voxel_size_m=0.02, min_points=3)
    cloud = rng.normal(0, 5.0, (20000, 3)).astype(np.float32)
    cloud[:10000] = np.round(cloud[:10000])  # piles of points on lattice nodes: voxels >= 3
    ok = kernel(cloud, fine.voxel_size_m, fine.max_range_m, fine.min_points, _DENSE_MAX_CELLS)[0]
    assert not ok
    assert_same_moments(cloud, fine)


def test_degenerate_inputs() -> None:
    assert not describe(np.zeros((0, 4), np.float32)).any()
    assert not describe(np.full((10, 3), np.nan, np.float32)).any()
    with pytest.raises(ConfigError, match="t_e must be in"):
        NdtHistogram(t_e=1.5)
