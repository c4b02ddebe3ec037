"""The ``ndt`` adapter's internals: the compiled NDT kernel and the warm source cache."""

from __future__ import annotations

import numpy as np
from helpers.odometry_data import Seq

from pipeline.odometry import get_adapter, run_sequence
from pipeline.odometry.base import Schedule
from pipeline.odometry.common import DownsampleCache, se3_exp, voxel_downsample, voxel_keys
from pipeline.odometry.ndt import NdtOdometry, VoxelMap
from pipeline.sequence import SequenceReader


def _room(rng: np.random.Generator) -> np.ndarray:
    """(18000, 3) points [m] of a noisy box room: two walls and the floor."""
    n = 6000
    u = rng.uniform(-8, 8, size=(n, 2))
    walls = [np.c_[u[:, 0], np.full(n, 8.0), u[:, 1] / 4],
             np.c_[np.full(n, -8.0), u[:, 0], u[:, 1] / 4],
             np.c_[u, np.full(n, -1.5)]]
    return np.vstack(walls) + rng.normal(0, 0.05, (3 * n, 3))


def _map_and_source(rng: np.random.Generator) -> tuple[NdtOdometry, np.ndarray]:
    """A voxel map of a noisy box room (walls, floor) and a source cloud of the same room."""
    room = _room(rng)
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


def _voxels_by_numpy(points: np.ndarray, resolution: float, min_points: int) -> tuple:
    """The voxel map by plain numpy (np.unique, batched eigh): the reference of
    ``build_voxels``."""
    keys, inv, counts = np.unique(voxel_keys(points, resolution), return_inverse=True,
                                  return_counts=True)
    keep = counts >= min_points
    means = np.stack([np.bincount(inv, points[:, k]) for k in range(3)], 1) / counts[:, None]
    d = points - means[inv]
    cov = np.einsum("ni,nj->nij", d, d)
    cov = np.stack([np.bincount(inv, cov[:, i, j]) for i in range(3) for j in range(3)], 1)
    cov = cov.reshape(-1, 3, 3) / np.maximum(counts - 1.0, 1.0)[:, None, None]
    evals, evecs = np.linalg.eigh(cov[keep])
    evals = np.maximum(evals, np.maximum(0.01 * evals[:, 2:3], 1e-6))
    inv_covs = np.einsum("kij,kj,klj->kil", evecs, 1.0 / evals, evecs)
    return keys[keep], means[keep], inv_covs


def test_voxel_map_matches_numpy(rng: np.random.Generator) -> None:
    """The compiled hash-table build gives numpy's voxels: same keys (sorted), means and
    clamped inverse covariances, also far from the origin and with degenerate (planar,
    linear) voxels, whose eigenvalues are clamped."""
    line = np.c_[np.linspace(0, 30, 400), np.zeros(400), np.zeros(400)] + 0.3
    far = rng.normal(0, 3, (3000, 3)) + np.array([4000.0, -2500.0, 30.0])
    room = _room(rng)
    for points in (room, far, np.vstack([far, line])):
        for resolution in (0.7, 2.0, 5.0):
            ref = _voxels_by_numpy(points, resolution, 5)
            got = VoxelMap.build(points, resolution, 5)
            np.testing.assert_array_equal(got.keys, ref[0])
            np.testing.assert_allclose(got.means, ref[1], rtol=0, atol=1e-9)
            scale = np.abs(ref[2]).max(axis=(1, 2))[:, None, None]
            np.testing.assert_allclose(got.inv_covs / scale, ref[2] / scale, rtol=0, atol=1e-9)


def test_hessian_and_gradient_match_the_per_pair_sums(rng: np.random.Generator) -> None:
    """H = sum w J^T C J and g = sum w J^T C e over the point-voxel pairs, formed directly
    per pair in numpy, equal the kernel's per-voxel moment sums."""
    odom, source = _map_and_source(rng)
    T = se3_exp(np.array([0.05, -0.02, 0.3, 0.4, -0.3, 0.1]))
    score, H, g, pairs = odom._evaluate(source, T)
    v = odom.voxels
    R, t = T[:3, :3], T[:3, 3]
    q = source @ R.T + t
    idx = np.searchsorted(v.keys, voxel_keys(q, v.resolution))
    idx = np.minimum(idx, len(v.keys) - 1)
    hit = v.keys[idx] == voxel_keys(q, v.resolution)
    p, q, idx = source[hit], q[hit], idx[hit]
    C, e = v.inv_covs[idx], q - v.means[idx]
    m = np.einsum("ni,nij,nj->n", e, C, e)
    w = -odom.d1 * odom.d2 * np.exp(-0.5 * odom.d2 * m)
    cross = np.zeros((len(p), 3, 3))  # -[p]x
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = p[:, 2], -p[:, 1], p[:, 0]
    cross -= cross.transpose(0, 2, 1)
    J = np.concatenate([R @ cross, np.broadcast_to(R, (len(p), 3, 3))], axis=2)
    H_ref = np.einsum("n,nia,nij,njb->ab", w, J, C, J)
    g_ref = np.einsum("n,nia,nij,nj->a", w, J, C, e)
    assert pairs == len(p) > 1000
    np.testing.assert_allclose(score, np.sum(-odom.d1 * np.exp(-0.5 * odom.d2 * m)), rtol=1e-12)
    np.testing.assert_allclose(H, H_ref, rtol=1e-9, atol=1e-9 * np.abs(H_ref).max())
    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-9 * np.abs(g_ref).max())


def _levenberg_by_hand(odom: NdtOdometry, source: np.ndarray, guess: np.ndarray,
                       max_iterations: int, convergence: float) -> tuple[np.ndarray, int]:
    """The damped Gauss-Newton loop ``ndt_align`` documents, written out in Python over the
    full ``ndt_terms`` at every candidate; also returns the number of rejected steps."""
    from pipeline.odometry.ndt_kernel import compose_se3_exp, solve6

    T = guess.copy()
    score, H, g, _ = odom._evaluate(source, T)
    lam, rejected = 1e-4, 0
    for _ in range(max_iterations):
        damped = H.copy()
        damped[np.diag_indices(6)] += lam * np.maximum(np.diag(H), 1e-9)
        step, ok = solve6(damped, g)
        assert ok
        cand = compose_se3_exp(T, -step)
        c_score, c_H, c_g, c_n = odom._evaluate(source, cand)
        if c_score > score and c_n >= 6:
            T, score, H, g = cand, c_score, c_H, c_g
            lam = max(lam * 0.1, 1e-7)
            if np.sqrt(np.sum(step**2)) < convergence:
                break
        else:
            rejected += 1
            lam *= 10.0
            if lam > 1e3:
                break
    return T, rejected


def test_align_equals_the_levenberg_loop_with_every_term(rng: np.random.Generator) -> None:
    """``ndt_align`` assembles the Hessian and gradient only for the steps it keeps; the pose
    it returns is bit for bit the loop's that assembles them at every candidate, also when
    steps are rejected."""
    from pipeline.odometry.ndt_kernel import ndt_align

    odom, source = _map_and_source(rng)
    v = odom.voxels
    rejected_total = 0
    for xi in ([0.05, -0.02, 0.3, 0.4, -0.3, 0.1], [0.0, 0.0, 0.02, 0.05, 0.0, 0.0],
               [0.1, 0.1, -0.4, 1.2, 0.8, -0.2]):
        guess = se3_exp(np.array(xi))
        for convergence in (1e-3, 1e-9):  # 1e-9: runs into rejected steps near the optimum
            ref, rejected = _levenberg_by_hand(odom, source, guess, 15, convergence)
            got, optimised = ndt_align(source, guess, v.slot_key, v.slot_index, v.means,
                                       v.inv_covs, 1.0 / v.resolution, odom._offsets, odom.d1,
                                       odom.d2, 15, convergence)
            assert optimised
            np.testing.assert_array_equal(got, ref)
            rejected_total += rejected
    assert rejected_total > 0
