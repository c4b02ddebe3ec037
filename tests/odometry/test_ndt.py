"""The ``ndt`` adapter's internals: the compiled NDT kernel and the warm source cache."""

from __future__ import annotations

import numpy as np
from odometry_data import Seq

from pipeline.odometry import get_adapter, run_sequence
from pipeline.odometry.base import Schedule
from pipeline.odometry.common import DownsampleCache, se3_exp, voxel_downsample
from pipeline.odometry.ndt import NdtOdometry, VoxelMap
from pipeline.sequence import SequenceReader


def _map_and_source(rng: np.random.Generator) -> tuple[NdtOdometry, np.ndarray]:
    """A voxel map of a noisy box room (walls, floor) and a source cloud of the same room."""
    n = 6000
    u = rng.uniform(-8, 8, size=(n, 2))
    walls = [np.c_[u[:, 0], np.full(n, 8.0), u[:, 1] / 4],
             np.c_[np.full(n, -8.0), u[:, 0], u[:, 1] / 4],
             np.c_[u, np.full(n, -1.5)]]
    room = np.vstack(walls) + rng.normal(0, 0.05, (3 * n, 3))
    odom = NdtOdometry({"resolution": 2.0, "keyframe_interval": 4.0})
    odom.voxels = VoxelMap.build(room, 2.0, 5)
    return odom, voxel_downsample(room[::7], 0.5)


def test_gradient_matches_finite_differences_of_the_score(rng: np.random.Generator) -> None:
    """g = -d score / d xi for the right perturbation T exp(xi) (the step _align takes)."""
    odom, source = _map_and_source(rng)
    T = se3_exp(np.array([0.02, -0.01, 0.03, 0.2, -0.1, 0.05]))
    _, H, g, pairs = odom._evaluate(source, T)
    assert pairs > 1000
    eps = 1e-6
    fd = np.empty(6)
    for j in range(6):
        step = np.zeros(6)
        step[j] = eps
        plus = odom._evaluate(source, T @ se3_exp(step))[0]
        minus = odom._evaluate(source, T @ se3_exp(-step))[0]
        fd[j] = -(plus - minus) / (2 * eps)
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-6 * np.abs(g).max())
    np.testing.assert_allclose(H, H.T)
    assert np.linalg.eigvalsh(H).min() > 0  # Gauss-Newton Hessian of positive weights


def test_kernel_pairs_every_source_point_with_its_voxel(rng: np.random.Generator) -> None:
    """At the identity the pair count equals the points that fall into a map voxel."""
    odom, source = _map_and_source(rng)
    _, _, _, pairs = odom._evaluate(source, np.eye(4))
    keys = np.floor(source / 2.0).astype(np.int64)
    occupied = {tuple(k) for k in np.floor(odom.voxels.means / 2.0).astype(np.int64)}
    assert pairs == sum(tuple(k) in occupied for k in keys)


def test_warm_cache_gives_the_bitwise_same_trajectory(synthetic_seq: Seq) -> None:
    adapter = get_adapter("ndt")
    with SequenceReader(synthetic_seq.path) as reader:
        scans = list(reader)
    schedule = Schedule.constant(adapter.space.defaults(), len(scans))
    cold = adapter.run(scans, schedule)
    adapter.warm(scans)
    assert len(adapter.sources) == len(scans)  # type: ignore[attr-defined]
    warm = adapter.run(scans, schedule)
    fresh = run_sequence(adapter, synthetic_seq.path, adapter.space.defaults())  # misses
    assert len(get_adapter("ndt").sources) == 0  # type: ignore[attr-defined]  # per instance
    np.testing.assert_array_equal(cold.T_world_lidar, warm.T_world_lidar)
    np.testing.assert_array_equal(cold.T_world_lidar, fresh.T_world_lidar)


def test_cache_is_keyed_by_the_array_and_the_voxel_size(rng: np.random.Generator) -> None:
    a = rng.uniform(-10, 10, (500, 4)).astype(np.float32)
    b = a.copy()
    expected = voxel_downsample(a[:, :3], 1.0)
    sources = DownsampleCache()
    sources.fill([a[:, :3]], 1.0)
    a[:, 0] += 100.0  # breaks the contract on purpose: shows the hit comes from the cache
    np.testing.assert_array_equal(sources.get(a[:, :3], 1.0), expected)
    # another array (same values as before) or another voxel size: computed, not cached
    np.testing.assert_array_equal(sources.get(b[:, :3], 1.0), expected)
    assert sources.get(b[:, :3], 1.0) is not sources.get(a[:, :3], 1.0)
    np.testing.assert_array_equal(sources.get(a[:, :3], 2.0), voxel_downsample(a[:, :3], 2.0))
