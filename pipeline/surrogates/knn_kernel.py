"""The numba kernels of the grouped kNN search (pipeline/surrogates/knn_search.py,
``TrialGroups``): the value of the k nearest rows of many query points (``knn_mean``) and the
nearest trial vectors of a few query points (``nearest_trials``).

Imported by the search on first use; without numba it uses ``knn_mean_numpy`` and the groups'
kd-trees, which give the same values (tests/test_knn_kernel.py compares both, ties included;
tests/test_runtime.py compares them with scikit-learn's kNN over every row).

The k nearest rows of a query point are the k smallest pairs (trial a of group g, frame j of
group g) by squared distance d = trial_d2 + frame_d2, ties ordered by (g, a, j): the order in
which the merge before issue 33 met them, and the order of ``knn_mean_numpy``'s stable sort.
``knn_mean`` finds them without merging: a bound tau >= the k-th distance, read off a few
corners of the sorted lists, gathers the pairs within it (a few more than k), and their
ranks by (d, order) pick the k. A point whose gathered pairs overflow the buffer is merged as
before, its best list seeded at the bound.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

GATHER = 3
"""The buffer of gathered pairs holds GATHER * k of them (about 1.5 k are gathered)."""


@numba.njit(cache=True, nogil=True)
def knn_mean(
    trial_d2: NDArray[np.float64],
    trial_pos: NDArray[np.int64],
    frame_d2: NDArray[np.float64],
    frame_row0: NDArray[np.int64],
    rows_t: NDArray[np.float64],
    k: int,
    risk: float = 0.0,
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Mean (+ risk * std) of the targets of the k nearest rows of each query point: (n,).

    trial_d2, trial_pos (n, G, k): squared distances (ascending, inf-padded) and block positions
    of each query's k nearest trial vectors in group g; frame_d2, frame_row0 (G, k): squared
    E-distances (ascending, inf-padded) and first rows of the group's k nearest frames; rows_t
    (M,) the targets. A row's squared joint distance is trial_d2 + frame_d2; the k nearest are
    those of the module docstring (ties by group, trial, frame). The value is
    ``knn_search.canonical_value`` of their k targets (the same bits for the same neighbours,
    whatever order they were found in): their mean, plus risk times their population std when
    risk > 0.
    """
    n, width = trial_d2.shape[0], trial_d2.shape[2]
    depth = frame_d2.shape[1]
    whole_a, whole_j = _corners(k, width, depth)
    half_a, half_j = _corners((k + 1) // 2, width, depth)
    out = np.empty(n)
    cap = GATHER * k
    pair_d = np.empty(cap)
    pair_row = np.empty(cap, np.int64)
    best_d = np.empty(k)
    best_row = np.empty(k, np.int64)
    chosen = np.empty(k)
    ordered = np.empty(k)
    for c in range(n):
        tau = _bound(trial_d2[c], frame_d2, whole_a, whole_j, half_a, half_j)
        m = _gather(trial_d2[c], trial_pos[c], frame_d2, frame_row0, tau, pair_d, pair_row)
        if m >= 0:
            _pick(pair_d, pair_row, m, rows_t, k, chosen)
        else:  # more pairs within tau than the buffer holds: merge
            _merge(trial_d2[c], trial_pos[c], frame_d2, frame_row0, tau, best_d, best_row)
            for i in range(k):
                chosen[i] = rows_t[best_row[i]]
        out[c] = _value(chosen, ordered, k, risk)
    return out


@numba.njit(cache=True, nogil=True)
def _corners(q: int, width: int,
             depth: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """Corners (a, j) (0-based) of one group's sorted lists with (a + 1)(j + 1) >= q, the
    fewest a for each j: the pairs a' <= a, j' <= j of a group are q rows, all within
    trial_d2[a] + frame_d2[j]."""
    rows_a = np.empty(q, np.int64)
    rows_j = np.empty(q, np.int64)
    n = 0
    for r1 in range(1, min(q, width) + 1):
        r2 = (q + r1 - 1) // r1
        if r2 <= depth and (n == 0 or r2 - 1 < rows_j[n - 1]):
            rows_a[n] = r1 - 1
            rows_j[n] = r2 - 1
            n += 1
    return rows_a[:n], rows_j[:n]


@numba.njit(cache=True, nogil=True, inline="always")
def _bound(
    trial_d2: NDArray[np.float64], frame_d2: NDArray[np.float64],
    whole_a: NDArray[np.int64], whole_j: NDArray[np.int64],
    half_a: NDArray[np.int64], half_j: NDArray[np.int64],
) -> float:  # pragma: no cover - compiled
    """tau >= the k-th smallest pair distance of one query point (trial_d2 (G, k)): the least
    corner holding k rows of one group, or ceil(k / 2) rows of each of two groups."""
    tau = np.inf
    low1 = np.inf
    low2 = np.inf
    for g in range(trial_d2.shape[0]):
        for f in range(len(whole_a)):
            tau = min(tau, trial_d2[g, whole_a[f]] + frame_d2[g, whole_j[f]])
        half = np.inf
        for f in range(len(half_a)):
            half = min(half, trial_d2[g, half_a[f]] + frame_d2[g, half_j[f]])
        if half < low1:
            low2 = low1
            low1 = half
        elif half < low2:
            low2 = half
    return min(tau, low2)


@numba.njit(cache=True, nogil=True, inline="always")
def _gather(
    trial_d2: NDArray[np.float64], trial_pos: NDArray[np.int64],
    frame_d2: NDArray[np.float64], frame_row0: NDArray[np.int64], tau: float,
    pair_d: NDArray[np.float64], pair_row: NDArray[np.int64],
) -> int:  # pragma: no cover - compiled
    """The pairs of one query point within tau, in (g, a, j) order, into pair_d / pair_row:
    their number, or -1 when they do not fit (or tau is inf). Both lists are sorted, so a row
    of trials (and a group) is left at its first pair beyond tau."""
    if not tau < np.inf:
        return -1
    m = 0
    for g in range(trial_d2.shape[0]):
        for a in range(trial_d2.shape[1]):
            da = trial_d2[g, a]
            if da + frame_d2[g, 0] > tau:
                break
            for j in range(frame_d2.shape[1]):
                d = da + frame_d2[g, j]
                if d > tau:
                    break
                if m == len(pair_d):
                    return -1
                pair_d[m] = d
                pair_row[m] = frame_row0[g, j] + trial_pos[g, a]
                m += 1
    return m


@numba.njit(cache=True, nogil=True, inline="always")
def _pick(
    pair_d: NDArray[np.float64], pair_row: NDArray[np.int64], m: int,
    rows_t: NDArray[np.float64], k: int, chosen: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The targets of the k first of m gathered pairs by (distance, gathering order) into
    chosen (k,): a pair's rank is the number of pairs before it in that order."""
    q = 0
    for i in range(m):
        if _rank(pair_d, m, i) < k:
            chosen[q] = rows_t[pair_row[i]]
            q += 1


@numba.njit(cache=True, nogil=True, inline="always")
def _rank(values: NDArray[np.float64], n: int, i: int) -> int:  # pragma: no cover - compiled
    """How many of values[:n] come before values[i] by value, then position (a stable sort's
    place for it)."""
    v = values[i]
    rank = 0
    same = 0
    for i2 in range(n):
        rank += values[i2] < v
        same += values[i2] == v
    if same > 1:  # equal values: those before it in the array come first
        for i2 in range(i):
            rank += values[i2] == v
    return rank


@numba.njit(cache=True, nogil=True, inline="always")
def _merge(
    trial_d2: NDArray[np.float64], trial_pos: NDArray[np.int64],
    frame_d2: NDArray[np.float64], frame_row0: NDArray[np.int64], tau: float,
    best_d: NDArray[np.float64], best_row: NDArray[np.int64],
) -> None:  # pragma: no cover - compiled
    """The k nearest rows of one query point by a merge of its pairs in (g, a, j) order into a
    sorted best list (best_d, best_row (k,)) seeded just above tau: a pair enters before the
    first entry farther than it, so equal distances keep the merge's order."""
    k = len(best_d)
    best_d[:] = np.nextafter(tau, np.inf)
    best_row[:] = 0
    for g in range(trial_d2.shape[0]):
        for a in range(trial_d2.shape[1]):
            da = trial_d2[g, a]
            if da + frame_d2[g, 0] >= best_d[k - 1]:
                break
            for j in range(frame_d2.shape[1]):
                d = da + frame_d2[g, j]
                if d >= best_d[k - 1]:
                    break
                _insert(best_d, best_row, k, d, frame_row0[g, j] + trial_pos[g, a])


@numba.njit(cache=True, nogil=True, inline="always")
def _insert(keys: NDArray[np.float64], items: NDArray[np.int64], n: int, key: float,
            item: int) -> None:  # pragma: no cover - compiled
    """(key, item) into the first n of keys, items (sorted by key), after every entry with an
    equal key; the last entry drops out."""
    m = n - 1
    while m > 0 and keys[m - 1] > key:
        keys[m] = keys[m - 1]
        items[m] = items[m - 1]
        m -= 1
    keys[m] = key
    items[m] = item


@numba.njit(cache=True, nogil=True, inline="always")
def _value(chosen: NDArray[np.float64], ordered: NDArray[np.float64], k: int,
           risk: float) -> float:  # pragma: no cover - compiled
    """``knn_search.canonical_value`` of the k targets chosen (k,): sorted ascending by their
    ranks into ordered (k,), summed left to right; mean (+ risk * population std)."""
    for i in range(k):
        ordered[_rank(chosen, k, i)] = chosen[i]
    total = 0.0
    for i in range(k):
        total += ordered[i]
    mean = total / k
    if risk == 0.0:
        return mean
    squares = 0.0
    for i in range(k):
        dev = ordered[i] - mean
        squares += dev * dev
    return mean + risk * np.sqrt(squares / k)


NEAR_TIE = 1e-9
"""Relative gap below which the k-th and the next trial of ``nearest_trials`` count as tied."""


@numba.njit(cache=True, nogil=True)
def nearest_trials(
    points: NDArray[np.float64], trials: NDArray[np.float64], order: NDArray[np.int64],
    leaf_start: NDArray[np.int64], leaf_box: NDArray[np.float64], k: int,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:  # pragma: no cover
    """The k nearest trial vectors of each point in every group, as the groups' kd-trees give
    them: squared distances and block positions (n, G, k) (ascending; inf and 0 past a
    group's size) and whether that answer is sure (n,).

    points (n, P); trials (G, T, P): each group's trial vectors leaf by leaf (order (G, T):
    their positions in the group's block), leaf l of group g being
    trials[g, leaf_start[g, l] : leaf_start[g, l + 1]] (L + 1 starts; empty leaves at the
    end), inside the box leaf_box[g, l] = (lowest, highest) (2, P). The leaves are
    visited nearest box first, until the nearest left is farther than the (k + 1)-th nearest
    trial so far.

    scipy's ``cKDTree.query`` returns the k nearest by the squared distance it sums (the same
    sum here, ``_sqeuclidean``) as sqrt(sum), which the search squares again: so does this.
    Its answer is the same as long as those sums do not tie: a point is not sure when, in some
    group, two of its k nearest have the same sum (the tree's order between them is its own)
    or the k-th and the next are within NEAR_TIE of each other (the tree's pruning rounds its
    bounds); the search asks the tree for those points.
    """
    n, n_params = points.shape
    n_groups, n_leaves = leaf_start.shape[0], leaf_start.shape[1] - 1
    d2 = np.full((n, n_groups, k), np.inf)
    pos = np.zeros((n, n_groups, k), np.int64)
    sure = np.ones(n, np.bool_)
    best_s = np.empty(k + 1)
    best_t = np.empty(k + 1, np.int64)
    bound = np.empty(n_leaves)
    diff = np.empty(n_params)
    for i in range(n):
        for g in range(n_groups):
            size = leaf_start[g, n_leaves]
            kk = min(k, size)
            keep = min(kk + 1, size)
            best_s[:keep] = np.inf
            for leaf in range(n_leaves):
                bound[leaf] = _box_gap(leaf_box, g, leaf, points, i, n_params, diff)
            while True:
                nearest = -1
                near = np.inf
                for leaf in range(n_leaves):
                    if bound[leaf] < near:
                        near = bound[leaf]
                        nearest = leaf
                if nearest < 0 or near > best_s[keep - 1]:
                    break  # every trial left is farther than the (k + 1)-th so far
                bound[nearest] = np.inf
                for t in range(leaf_start[g, nearest], leaf_start[g, nearest + 1]):
                    s = _sqeuclidean(trials, g, t, points, i, n_params, diff)
                    if s >= best_s[keep - 1]:
                        continue
                    _insert(best_s, best_t, keep, s, t)
            for a in range(kk):
                r = np.sqrt(best_s[a])
                d2[i, g, a] = r * r
                pos[i, g, a] = order[g, best_t[a]]
                if a > 0 and not best_s[a - 1] < best_s[a]:
                    sure[i] = False
            if keep > kk and not best_s[kk] - best_s[kk - 1] > NEAR_TIE * best_s[kk]:
                sure[i] = False
    return d2, pos, sure


@numba.njit(cache=True, nogil=True, inline="always")
def _box_gap(leaf_box: NDArray[np.float64], g: int, leaf: int, points: NDArray[np.float64],
             i: int, n: int, diff: NDArray[np.float64]) -> float:  # pragma: no cover - compiled
    """The squared distance of points[i] to the box leaf_box[g, leaf] (n coordinates; diff (n,)
    scratch), summed as ``_sqeuclidean`` sums: no more than ``_sqeuclidean`` of any point in
    the box (every gap is at most that point's coordinate difference, and the sums are in the
    same order); inf for an empty box (lowest > highest)."""
    for p in range(n):
        diff[p] = _gap(leaf_box, g, leaf, points, i, p)
    return _tree_sum(diff, n)


@numba.njit(cache=True, nogil=True, inline="always")
def _gap(leaf_box: NDArray[np.float64], g: int, leaf: int, points: NDArray[np.float64], i: int,
         p: int) -> float:  # pragma: no cover - compiled
    """How far coordinate p of points[i] lies outside [lowest, highest] of the box (0 inside,
    inf for an empty box)."""
    low = leaf_box[g, leaf, 0, p]
    high = leaf_box[g, leaf, 1, p]
    x = points[i, p]
    if low > high:
        return np.inf
    if x < low:
        return low - x
    if x > high:
        return x - high
    return 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _sqeuclidean(trials: NDArray[np.float64], g: int, t: int, points: NDArray[np.float64],
                 i: int, n: int, diff: NDArray[np.float64]) -> float:  # pragma: no cover
    """|trials[g, t] - points[i]|^2 (n coordinates; diff (n,) scratch), as scipy's kd-tree
    sums it (``_tree_sum``)."""
    for p in range(n):
        diff[p] = trials[g, t, p] - points[i, p]
    return _tree_sum(diff, n)


@numba.njit(cache=True, nogil=True, inline="always")
def _tree_sum(diff: NDArray[np.float64], n: int) -> float:  # pragma: no cover - compiled
    """The sum of diff[:n] squared in the order of scipy's kd-tree
    (``sqeuclidean_distance_double``): four partial sums over blocks of four coordinates, added
    in order, then the rest one by one."""
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    acc3 = 0.0
    p = 0
    while p + 4 <= n:
        acc0 += diff[p] * diff[p]
        acc1 += diff[p + 1] * diff[p + 1]
        acc2 += diff[p + 2] * diff[p + 2]
        acc3 += diff[p + 3] * diff[p + 3]
        p += 4
    s = acc0 + acc1 + acc2 + acc3
    while p < n:
        s += diff[p] * diff[p]
        p += 1
    return s
