"""The compiled parts of the ``ndt`` adapter (numba): the voxel map of a keyframe, the NDT
score with its Gauss-Newton terms, and the whole Levenberg-damped registration of one scan.

Why compiled as a whole: a scan takes about 10 Gauss-Newton steps of a few hundred source
points each, so in numpy most of an NDT run was call overhead around the per-point kernel (a
6x6 solve, Rodrigues, 4x4 products, a batched 3x3 eigendecomposition per keyframe), not the
kernel itself. The algorithm is documented in ``pipeline/odometry/ndt.py``; arrays are
float64 and contiguous, frames as named there.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from pipeline.odometry.common import F64
from pipeline.odometry.voxel_key import packed_voxel_key

_JACOBI_SWEEPS = 32
"""Cyclic Jacobi sweeps of a 3x3 eigendecomposition at most (it converges in 4-6)."""


@numba.njit(cache=True, nogil=True)
def clamped_inverse(cov: F64, out: F64, a: F64, v: F64) -> None:  # pragma: no cover
    """``out`` (3, 3) = the inverse of the symmetric ``cov`` (3, 3) with its eigenvalues
    clamped to >= 1 % of the largest (and >= 1e-6): Magnusson's regularisation. Eigenvectors
    by cyclic Jacobi rotations, accurate to the last bits for a 3x3 matrix; ``a`` and ``v``
    are (3, 3) scratch arrays (the rotated matrix and the eigenvectors)."""
    for i in range(3):
        for j in range(3):
            a[i, j] = cov[i, j]
            v[i, j] = 1.0 if i == j else 0.0
    for _ in range(_JACOBI_SWEEPS):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        scale = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if a[p, q] == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
            t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):  # a <- a G (columns p, q)
                akp, akq = a[k, p], a[k, q]
                a[k, p] = c * akp - s * akq
                a[k, q] = s * akp + c * akq
            for k in range(3):  # a <- G^T a (rows p, q)
                apk, aqk = a[p, k], a[q, k]
                a[p, k] = c * apk - s * aqk
                a[q, k] = s * apk + c * aqk
            for k in range(3):  # v <- v G
                vkp, vkq = v[k, p], v[k, q]
                v[k, p] = c * vkp - s * vkq
                v[k, q] = s * vkp + c * vkq
    largest = max(a[0, 0], a[1, 1], a[2, 2])
    floor = max(0.01 * largest, 1e-6)
    l0 = 1.0 / max(a[0, 0], floor)
    l1 = 1.0 / max(a[1, 1], floor)
    l2 = 1.0 / max(a[2, 2], floor)
    for i in range(3):
        for j in range(3):
            out[i, j] = v[i, 0] * l0 * v[j, 0] + v[i, 1] * l1 * v[j, 1] + v[i, 2] * l2 * v[j, 2]


_EMPTY = np.int64(-1)
"""An empty slot of the voxel hash table (packed keys are >= 0)."""


@numba.njit(cache=True, nogil=True)
def _hash_slot(key: np.int64, mask: np.int64) -> np.int64:  # pragma: no cover - compiled
    """Start slot of ``key`` in a table of mask + 1 (a power of two) slots (Fibonacci
    hashing of the 63-bit key)."""
    h = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64(h >> np.uint64(40)) & mask


@numba.njit(cache=True, nogil=True)
def _table_size(n: int) -> int:  # pragma: no cover - compiled
    """Slots of a hash table for n keys: the smallest power of two >= max(2n, 2)."""
    size = 2
    while size < 2 * n:
        size *= 2
    return size


@numba.njit(cache=True, nogil=True)
def _probe(table_key: NDArray[np.int64], key: np.int64) -> np.int64:  # pragma: no cover
    """The slot of ``key`` in the open-addressing table ``table_key`` (linear probing), or
    the empty slot where it belongs."""
    mask = np.int64(len(table_key) - 1)
    h = _hash_slot(key, mask)
    while table_key[h] != _EMPTY and table_key[h] != key:
        h = (h + 1) & mask
    return h


@numba.njit(cache=True, nogil=True)
def build_voxels(points_world: F64, resolution: float,
                 min_points: int) -> tuple[NDArray[np.int64], F64, F64]:  # pragma: no cover
    """NDT voxels of ``points_world`` (M, 3) [m] at ``resolution`` [m]: sorted keys (K,),
    means (K, 3) [m] and regularised inverse covariances (K, 3, 3) [1/m^2] of the voxels
    with >= ``min_points`` points.

    One pass in input order gathers each voxel's moments in a hash table (open addressing),
    relative to the voxel's first point, which keeps them well conditioned far from the
    origin; only the occupied voxels are then sorted by key."""
    n = points_world.shape[0]
    inv_res = 1.0 / resolution
    no_offset = np.zeros((1, 3), np.int64)
    size = _table_size(n)
    table_key = np.full(size, _EMPTY, np.int64)
    table_voxel = np.empty(size, np.int64)
    voxel_key = np.empty(n, np.int64)
    ref = np.empty((n, 3))
    count = np.empty(n, np.int64)  # rows 0..used-1 are zeroed when their voxel is made
    sums = np.empty((n, 9))  # d0 d1 d2 d0d0 d0d1 d0d2 d1d1 d1d2 d2d2, d = point - ref
    used = 0
    last_key, v = _EMPTY, np.int64(0)
    for i in range(n):
        x, y, z = points_world[i, 0], points_world[i, 1], points_world[i, 2]
        key = packed_voxel_key(x, y, z, inv_res, no_offset, 0)
        if key != last_key:  # a scan's consecutive points often share a voxel
            h = _probe(table_key, key)
            if table_key[h] == _EMPTY:
                table_key[h] = key
                table_voxel[h] = used
                voxel_key[used] = key
                ref[used, 0], ref[used, 1], ref[used, 2] = x, y, z
                count[used] = 0
                sums[used, :] = 0.0
                used += 1
            v = table_voxel[h]
            last_key = key
        count[v] += 1
        d0, d1, d2 = x - ref[v, 0], y - ref[v, 1], z - ref[v, 2]
        sums[v, 0] += d0
        sums[v, 1] += d1
        sums[v, 2] += d2
        sums[v, 3] += d0 * d0
        sums[v, 4] += d0 * d1
        sums[v, 5] += d0 * d2
        sums[v, 6] += d1 * d1
        sums[v, 7] += d1 * d2
        sums[v, 8] += d2 * d2
    order = np.argsort(voxel_key[:used])
    out_keys = np.empty(used, np.int64)
    means = np.empty((used, 3))
    inv_covs = np.empty((used, 3, 3))
    cov = np.empty((3, 3))
    work = np.empty((2, 3, 3))
    k = 0
    for v in order:
        c = count[v]
        if c < min_points:
            continue
        mx, my, mz = sums[v, 0] / c, sums[v, 1] / c, sums[v, 2] / c
        unbias = c / (c - 1.0)
        cov[0, 0] = (sums[v, 3] / c - mx * mx) * unbias
        cov[0, 1] = cov[1, 0] = (sums[v, 4] / c - mx * my) * unbias
        cov[0, 2] = cov[2, 0] = (sums[v, 5] / c - mx * mz) * unbias
        cov[1, 1] = (sums[v, 6] / c - my * my) * unbias
        cov[1, 2] = cov[2, 1] = (sums[v, 7] / c - my * mz) * unbias
        cov[2, 2] = (sums[v, 8] / c - mz * mz) * unbias
        out_keys[k] = voxel_key[v]
        means[k, 0], means[k, 1], means[k, 2] = mx + ref[v, 0], my + ref[v, 1], mz + ref[v, 2]
        clamped_inverse(cov, inv_covs[k], work[0], work[1])
        k += 1
    return out_keys[:k].copy(), means[:k].copy(), inv_covs[:k].copy()


@numba.njit(cache=True, nogil=True)
def key_table(keys: NDArray[np.int64]) -> tuple[NDArray[np.int64],
                                               NDArray[np.int64]]:  # pragma: no cover
    """Open-addressing hash table of the voxel ``keys`` (K,): slot keys and slot indices into
    ``keys`` (S,), S a power of two >= 2K, empty slots -1 (``find_voxel`` reads it). A source
    point finds its voxel in about one probe instead of a binary search's log2(K)."""
    size = _table_size(len(keys))
    slot_key = np.full(size, _EMPTY, np.int64)
    slot_index = np.full(size, -1, np.int64)
    for i in range(len(keys)):  # keys are distinct: each lands in an empty slot
        h = _probe(slot_key, keys[i])
        slot_key[h] = keys[i]
        slot_index[h] = i
    return slot_key, slot_index


@numba.njit(cache=True, nogil=True)
def find_voxel(slot_key: NDArray[np.int64], slot_index: NDArray[np.int64],
               key: np.int64) -> np.int64:  # pragma: no cover - compiled
    """Index of ``key`` in the keys of ``key_table``, -1 when it is not a map voxel (an empty
    slot's index is -1)."""
    return slot_index[_probe(slot_key, key)]


@numba.njit(cache=True, nogil=True)
def transform_points(points: NDArray[np.float32], T: F64) -> F64:  # pragma: no cover
    """(N, 3) float64 points R p + t of the first three columns of ``points`` (N, >= 3)."""
    n = points.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        x, y, z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        for a in range(3):
            out[i, a] = T[a, 0] * x + T[a, 1] * y + T[a, 2] * z + T[a, 3]
    return out


# nonzeros (row, column, value) of the cross-product matrices [e_a]x, a = 0, 1, 2
_CROSS = np.array([[[1, 2, -1], [2, 1, 1]],
                   [[0, 2, 1], [2, 0, -1]],
                   [[0, 1, -1], [1, 0, 1]]], np.int64)


@numba.njit(cache=True, nogil=True)
def ndt_terms(source: F64, T: F64, slot_key: NDArray[np.int64], slot_index: NDArray[np.int64],
              means: F64, inv_covs: F64, inv_res: float, offsets: NDArray[np.int64], d1: float,
              d2: float) -> tuple[float, F64, F64, int]:  # pragma: no cover - compiled
    """Score, Hessian (6, 6) and gradient (6,) of the NDT objective, and the pair count:
    ``ndt_moments`` then ``ndt_assemble`` (whose docstrings give the formulas)."""
    score, pairs, Ms, cs, moments, used = ndt_moments(source, T, slot_key, slot_index, means,
                                                      inv_covs, inv_res, offsets, d1, d2)
    H, g = ndt_assemble(Ms, cs, moments, used)
    return score, H, g, pairs


@numba.njit(cache=True, nogil=True)
def ndt_moments(source: F64, T: F64, slot_key: NDArray[np.int64], slot_index: NDArray[np.int64],
                means: F64, inv_covs: F64, inv_res: float, offsets: NDArray[np.int64], d1: float,
                d2: float) -> tuple[float, int, F64, F64, F64, int]:  # pragma: no cover
    """The pass over the points of the NDT objective: score, pair count, and per paired voxel
    k < used its M (used, 3, 3), c (used, 3) and moments (used, 10), from which
    ``ndt_assemble`` forms the Hessian and gradient (``ndt_align`` does so only for a step it
    keeps).

    source (N, 3) points p [m] in the sensor frame; T (4, 4) the pose (R, t); slot_key,
    slot_index the ``key_table`` of the map's voxel keys, means (K, 3) mu, inv_covs (K, 3, 3)
    C; inv_res = 1 / resolution [1/m]; offsets (O, 3) voxel offsets searched around a point.

    Every point q = R p + t is paired with each map voxel of its own (and offset) voxel.
    With e = q - mu and m = e^T C e a pair contributes the score -d1 exp(-d2 m / 2); with the
    weight w = -d1 d2 exp(-d2 m / 2) and J = dq/dxi = R [A | I], A = -[p]x (right perturbation
    T exp(xi)), it contributes w J^T C J to the Hessian and w J^T C e to the gradient.

    Both sums are formed per voxel, in the sensor frame: with M = R^T C R, c = R^T (mu - t)
    and e' = R^T e = p - c, a pair adds only w, w e' and w e' e'^T to its voxel's moments
    (S0, S1, S2), and each voxel then adds, with P = S2 + S1 c^T + c S1^T + S0 c c^T
    (sum of w p p^T) and s = S1 + S0 c (sum of w p):
    gradient: rotation sum(w e' x M e') + c x M S1, translation M S1;
    Hessian: rotation-rotation sum_ij [e_a]x_ik M_ij [e_b]x_jl P_kl, rotation-translation
    columns s x M[:, b], translation-translation S0 M.
    Summation runs in point order, then in the order voxels were first paired, so the result
    is deterministic.
    """
    R = T[:3, :3]
    t = T[:3, 3]
    n_keys = means.shape[0]
    cap = min(source.shape[0] * offsets.shape[0], n_keys)
    slot = np.full(n_keys, -1, np.int64)
    Ms = np.empty((cap, 3, 3))
    cs = np.empty((cap, 3))
    moments = np.zeros((cap, 10))  # S0, S1 (3), S2 upper triangle (00 01 02 11 12 22)
    used = 0
    score = 0.0
    pairs = 0
    for i in range(source.shape[0]):
        px, py, pz = source[i, 0], source[i, 1], source[i, 2]
        qx = R[0, 0] * px + R[0, 1] * py + R[0, 2] * pz + t[0]
        qy = R[1, 0] * px + R[1, 1] * py + R[1, 2] * pz + t[1]
        qz = R[2, 0] * px + R[2, 1] * py + R[2, 2] * pz + t[2]
        for o in range(offsets.shape[0]):
            v = find_voxel(slot_key, slot_index, packed_voxel_key(qx, qy, qz, inv_res, offsets, o))
            if v < 0:
                continue
            k = slot[v]
            if k < 0:
                k = used
                slot[v] = k
                used += 1
                _voxel_in_sensor_frame(R, t, means, inv_covs, v, Ms, cs, k)
            pairs += 1
            e0, e1, e2 = px - cs[k, 0], py - cs[k, 1], pz - cs[k, 2]
            m0 = Ms[k, 0, 0] * e0 + Ms[k, 0, 1] * e1 + Ms[k, 0, 2] * e2
            m1 = Ms[k, 1, 0] * e0 + Ms[k, 1, 1] * e1 + Ms[k, 1, 2] * e2
            m2 = Ms[k, 2, 0] * e0 + Ms[k, 2, 1] * e1 + Ms[k, 2, 2] * e2
            ex = np.exp(-0.5 * d2 * (e0 * m0 + e1 * m1 + e2 * m2))
            score -= d1 * ex
            w = -d1 * d2 * ex
            moments[k, 0] += w
            moments[k, 1] += w * e0
            moments[k, 2] += w * e1
            moments[k, 3] += w * e2
            moments[k, 4] += w * e0 * e0
            moments[k, 5] += w * e0 * e1
            moments[k, 6] += w * e0 * e2
            moments[k, 7] += w * e1 * e1
            moments[k, 8] += w * e1 * e2
            moments[k, 9] += w * e2 * e2
    return score, pairs, Ms, cs, moments, used


@numba.njit(cache=True, nogil=True)
def ndt_assemble(Ms: F64, cs: F64, moments: F64, used: int) -> tuple[F64, F64]:  # pragma: no cover
    """Hessian (6, 6) and gradient (6,) from the first ``used`` voxels of ``ndt_moments``,
    summed in the order the voxels were first paired."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    P = np.empty((3, 3))
    for k in range(used):
        _add_voxel_terms(Ms, cs, moments, k, H, g, P)
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return H, g


@numba.njit(cache=True, nogil=True)
def _voxel_in_sensor_frame(R: F64, t: F64, means: F64, inv_covs: F64, v: int | np.int64, Ms: F64,
                           cs: F64, k: int) -> None:  # pragma: no cover - compiled
    """Ms[k] = R^T C R (3, 3) and cs[k] = R^T (mu - t) (3,) of map voxel v (C = inv_covs[v],
    mu = means[v])."""
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for i in range(3):
                acc += R[i, a] * (inv_covs[v, i, 0] * R[0, b] + inv_covs[v, i, 1] * R[1, b]
                                  + inv_covs[v, i, 2] * R[2, b])
            Ms[k, a, b] = acc
        cs[k, a] = (R[0, a] * (means[v, 0] - t[0]) + R[1, a] * (means[v, 1] - t[1])
                    + R[2, a] * (means[v, 2] - t[2]))


@numba.njit(cache=True, nogil=True)
def _add_voxel_terms(Ms: F64, cs: F64, moments: F64, k: int, H: F64, g: F64,
                     P: F64) -> None:  # pragma: no cover - compiled
    """Add voxel k's gradient (6,) and upper-triangle Hessian (6, 6) terms, from M = Ms[k],
    c = cs[k] and its moments (S0, S1, S2 upper triangle) = moments[k] (``ndt_terms``);
    P is a (3, 3) scratch array."""
    s0 = moments[k, 0]
    s1x, s1y, s1z = moments[k, 1], moments[k, 2], moments[k, 3]
    cx, cy, cz = cs[k, 0], cs[k, 1], cs[k, 2]
    # S2 (symmetric) and P = S2 + S1 c^T + c S1^T + S0 c c^T, the sum of w p p^T
    S2 = ((moments[k, 4], moments[k, 5], moments[k, 6]),
          (moments[k, 5], moments[k, 7], moments[k, 8]),
          (moments[k, 6], moments[k, 8], moments[k, 9]))
    s1 = (s1x, s1y, s1z)
    c = (cx, cy, cz)
    # u = M S1; gradient, translation: u
    u0 = Ms[k, 0, 0] * s1x + Ms[k, 0, 1] * s1y + Ms[k, 0, 2] * s1z
    u1 = Ms[k, 1, 0] * s1x + Ms[k, 1, 1] * s1y + Ms[k, 1, 2] * s1z
    u2 = Ms[k, 2, 0] * s1x + Ms[k, 2, 1] * s1y + Ms[k, 2, 2] * s1z
    g[3] += u0
    g[4] += u1
    g[5] += u2
    # gradient, rotation: sum(w e' x M e') + c x u, with Q = M S2 (sum of w (M e') e'^T)
    q21 = Ms[k, 2, 0] * S2[0][1] + Ms[k, 2, 1] * S2[1][1] + Ms[k, 2, 2] * S2[2][1]
    q12 = Ms[k, 1, 0] * S2[0][2] + Ms[k, 1, 1] * S2[1][2] + Ms[k, 1, 2] * S2[2][2]
    q02 = Ms[k, 0, 0] * S2[0][2] + Ms[k, 0, 1] * S2[1][2] + Ms[k, 0, 2] * S2[2][2]
    q20 = Ms[k, 2, 0] * S2[0][0] + Ms[k, 2, 1] * S2[1][0] + Ms[k, 2, 2] * S2[2][0]
    q10 = Ms[k, 1, 0] * S2[0][0] + Ms[k, 1, 1] * S2[1][0] + Ms[k, 1, 2] * S2[2][0]
    q01 = Ms[k, 0, 0] * S2[0][1] + Ms[k, 0, 1] * S2[1][1] + Ms[k, 0, 2] * S2[2][1]
    g[0] += q21 - q12 + cy * u2 - cz * u1
    g[1] += q02 - q20 + cz * u0 - cx * u2
    g[2] += q10 - q01 + cx * u1 - cy * u0
    for a in range(3):
        for b in range(3):
            P[a, b] = S2[a][b] + s1[a] * c[b] + c[a] * s1[b] + s0 * c[a] * c[b]
    s = (s1x + s0 * cx, s1y + s0 * cy, s1z + s0 * cz)  # sum of w p
    for a in range(3):
        for b in range(a, 3):  # rotation-rotation
            h = 0.0
            for x in range(2):
                i, kk, sa = _CROSS[a, x, 0], _CROSS[a, x, 1], _CROSS[a, x, 2]
                for y in range(2):
                    j, ll, sb = _CROSS[b, y, 0], _CROSS[b, y, 1], _CROSS[b, y, 2]
                    h += sa * sb * Ms[k, i, j] * P[kk, ll]
            H[a, b] += h
        a1, a2 = (a + 1) % 3, (a + 2) % 3
        for b in range(3):  # rotation-translation: (s x M[:, b])_a
            H[a, 3 + b] += s[a1] * Ms[k, a2, b] - s[a2] * Ms[k, a1, b]
        for b in range(a, 3):  # translation-translation
            H[3 + a, 3 + b] += s0 * Ms[k, a, b]


@numba.njit(cache=True, nogil=True)
def solve6(A: F64, b: F64) -> tuple[F64, bool]:  # pragma: no cover - compiled
    """x with A x = b for A (6, 6) by Gaussian elimination with partial pivoting; ok is
    False when a pivot is exactly zero (singular A)."""
    M = A.copy()
    x = b.copy()
    n = 6
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(M[r, col]) > abs(M[piv, col]):
                piv = r
        if M[piv, col] == 0.0:
            return x, False
        if piv != col:
            for c in range(n):
                M[col, c], M[piv, c] = M[piv, c], M[col, c]
            x[col], x[piv] = x[piv], x[col]
        for r in range(col + 1, n):
            f = M[r, col] / M[col, col]
            for c in range(col, n):
                M[r, c] -= f * M[col, c]
            x[r] -= f * x[col]
    for r in range(n - 1, -1, -1):
        acc = x[r]
        for c in range(r + 1, n):
            acc -= M[r, c] * x[c]
        x[r] = acc / M[r, r]
    return x, True


@numba.njit(cache=True, nogil=True)
def compose_se3_exp(T: F64, xi: F64) -> F64:  # pragma: no cover - compiled
    """T @ se3_exp(xi) (``common.se3_exp``: Rodrigues rotation, translation as is), (4, 4)."""
    wx, wy, wz = xi[0], xi[1], xi[2]
    theta = math.sqrt(wx * wx + wy * wy + wz * wz)
    K = np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])
    E = np.eye(4)
    if theta < 1e-10:
        a, b = 1.0, 0.0
    else:
        a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / (theta * theta)
    for i in range(3):
        for j in range(3):
            kk = K[i, 0] * K[0, j] + K[i, 1] * K[1, j] + K[i, 2] * K[2, j]
            E[i, j] += a * K[i, j] + b * kk
        E[i, 3] = xi[3 + i]
    out = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            out[i, j] = (T[i, 0] * E[0, j] + T[i, 1] * E[1, j] + T[i, 2] * E[2, j]
                         + T[i, 3] * E[3, j])
    return out


@numba.njit(cache=True, nogil=True)
def ndt_align(source: F64, guess: F64, slot_key: NDArray[np.int64],
              slot_index: NDArray[np.int64], means: F64, inv_covs: F64,
              inv_res: float, offsets: NDArray[np.int64], d1: float, d2: float,
              max_iterations: int, convergence: float) -> tuple[F64, bool]:  # pragma: no cover
    """Levenberg-damped Gauss-Newton on the NDT score from ``guess`` (4, 4): the best pose
    found and whether it was optimised (False: < 6 point-voxel pairs at the guess, which is
    returned as is). A step is kept only when the score rises (the damping then shrinks
    tenfold, else grows tenfold, giving up above 1e3); stop when |step| < ``convergence``."""
    T = guess.copy()
    score, H, g, n = ndt_terms(source, T, slot_key, slot_index, means, inv_covs, inv_res,
                               offsets, d1, d2)
    if n < 6:
        return T, False
    lam = 1e-4
    for _ in range(max_iterations):
        damped = H.copy()
        for k in range(6):
            damped[k, k] += lam * max(H[k, k], 1e-9)
        step, ok = solve6(damped, g)
        if not ok:
            break
        xi = -step
        cand = compose_se3_exp(T, xi)
        c_score, c_n, Ms, cs, moments, used = ndt_moments(source, cand, slot_key, slot_index,
                                                          means, inv_covs, inv_res, offsets,
                                                          d1, d2)
        if c_score > score and c_n >= 6:
            H, g = ndt_assemble(Ms, cs, moments, used)  # only for a kept step
            T, score = cand, c_score
            lam = max(lam * 0.1, 1e-7)
            if math.sqrt(xi[0] ** 2 + xi[1] ** 2 + xi[2] ** 2 + xi[3] ** 2 + xi[4] ** 2
                         + xi[5] ** 2) < convergence:
                break
        else:
            lam *= 10.0
            if lam > 1e3:
                break
    return T, True
