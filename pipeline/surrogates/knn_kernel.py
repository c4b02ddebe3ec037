"""The numba kernels of the grouped kNN search (pipeline/surrogates/knn_search.py,
``TrialGroups``): the value of the k nearest rows of many query points (``knn_mean``) and the
nearest trial vectors of a few query points (``nearest_trials``).

Imported by the search on first use; without numba it uses ``knn_mean_numpy`` and the groups'
kd-trees, which give the same values (tests/test_knn_kernel.py compares both, ties included;
tests/test_runtime.py compares them with scikit-learn's kNN over every row).

The k nearest rows of a query point are the k smallest pairs (trial a of group g, frame j of
group g) by squared distance d = trial_d2 + frame_d2, ties ordered by (g, a, j): the order
in which a plain merge of the sorted lists meets them, and the order of ``knn_mean_numpy``'s
stable sort.
``knn_mean`` merges the pairs in that order into a sorted best list, each after the entries
of its distance, within a bound tau >= the k-th distance read off a few corners of the sorted
lists (until the list holds k pairs; then within its k-th). The bound leaves about 1.3 k pairs
to merge, and the list grows from empty, so an insertion shifts only the pairs already in
(faster than ranking the pairs within the bound: docs/performance.md, "The online
selection").
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray


@numba.njit(cache=True, nogil=True)
def knn_mean(
    trial_d2: NDArray[np.float64],
    trial_pos: NDArray[np.int32],
    frame_d2: NDArray[np.float64],
    frame_row0: NDArray[np.int64],
    rows_t: NDArray[np.float64],
    k: int,
    risk: float = 0.0,
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """Mean (+ risk * std) of the targets of the k nearest rows of each query point: (n,).

    trial_d2, trial_pos (n, G, k): squared distances (ascending, inf-padded) and block positions
    (int32: half the bytes of int64 to read) of each query's k nearest trial vectors in group
    g; frame_d2, frame_row0 (G, k): squared E-distances (ascending, inf-padded) and first rows
    of the group's k nearest frames; rows_t (M,) the targets. A row's squared joint distance
    is trial_d2 + frame_d2; the k nearest are those of the module docstring (ties by group,
    trial, frame). The value is ``knn_search.canonical_value`` of their k targets (the same
    bits for the same neighbours, whatever order they were found in): their mean, plus risk
    times their population std when risk > 0.
    """
    n, width = trial_d2.shape[0], trial_d2.shape[2]
    depth = frame_d2.shape[1]
    whole_a, whole_j = _corners(k, width, depth)
    half_a, half_j = _corners((k + 1) // 2, width, depth)
    low, high = _sorting_network(k)
    out = np.empty(n)
    best_d = np.empty(k)
    best_row = np.zeros(k, np.int64)  # valid rows even if fewer than k pairs (k > rows)
    chosen = np.empty(k)
    for c in range(n):
        tau = _bound(trial_d2[c], frame_d2, whole_a, whole_j, half_a, half_j)
        _merge(trial_d2[c], trial_pos[c], frame_d2, frame_row0, tau, best_d, best_row)
        for i in range(k):
            chosen[i] = rows_t[best_row[i]]
        out[c] = _value(chosen, low, high, k, risk)
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
        if trial_d2[g, 0] + frame_d2[g, 0] >= min(tau, low2):
            continue  # no corner of the group is nearer (nor its lines of trials read)
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
def _merge(
    trial_d2: NDArray[np.float64], trial_pos: NDArray[np.int32],
    frame_d2: NDArray[np.float64], frame_row0: NDArray[np.int64], tau: float,
    best_d: NDArray[np.float64], best_row: NDArray[np.int64],
) -> None:  # pragma: no cover - compiled
    """The k nearest rows of one query point into best_d, best_row (k,), sorted by distance:
    its pairs within tau (>= the k-th distance) merged in (g, a, j) order, each entering
    after the entries of its distance, so equal distances keep the order of the module
    docstring. Both lists are sorted, so a row of trials (and a group) is left at its first
    pair beyond the limit: tau until k pairs are in, then the k-th so far (a pair equal to it
    comes after it)."""
    k = len(best_d)
    limit = np.nextafter(tau, np.inf)
    filled = 0
    for g in range(trial_d2.shape[0]):
        for a in range(trial_d2.shape[1]):
            da = trial_d2[g, a]
            if da + frame_d2[g, 0] >= limit:
                break
            for j in range(frame_d2.shape[1]):
                d = da + frame_d2[g, j]
                if d >= limit:
                    break
                filled = _push(best_d, best_row, filled, d, frame_row0[g, j] + trial_pos[g, a])
                if filled == k:
                    limit = best_d[k - 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _push(keys: NDArray[np.float64], items: NDArray[np.int64], filled: int, key: float,
          item: int) -> int:  # pragma: no cover - compiled
    """(key, item) into the first ``filled`` of keys, items (sorted by key) after every entry
    with an equal key, growing them up to their length (when full, the last entry drops out):
    the new number filled."""
    if filled < len(keys):
        filled += 1
    _insert(keys, items, filled, key, item)
    return filled


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
def _value(chosen: NDArray[np.float64], low: NDArray[np.int64], high: NDArray[np.int64], k: int,
           risk: float) -> float:  # pragma: no cover - compiled
    """``knn_search.canonical_value`` of the k targets chosen (k,): sorted ascending in place
    by the sorting network (low, high) (``_sorting_network``), summed left to right; mean
    (+ risk * population std). Equal targets are equal bits, so their order in the sorted
    list does not change a sum."""
    for q in range(len(low)):
        a, b = low[q], high[q]
        x, y = chosen[a], chosen[b]
        chosen[a] = min(x, y)  # branch-free compare-exchange: minsd, maxsd
        chosen[b] = max(x, y)
    total = 0.0
    for i in range(k):
        total += chosen[i]
    mean = total / k
    if risk == 0.0:
        return mean
    squares = 0.0
    for i in range(k):
        dev = chosen[i] - mean
        squares += dev * dev
    return mean + risk * np.sqrt(squares / k)


@numba.njit(cache=True, nogil=True)
def _sorting_network(n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """Batcher's odd-even merge sort of n values as compare-exchanges (low[q], high[q]):
    applied in order, each putting the smaller value at low[q], they sort any n values
    ascending. Built for the next power of two with the values past n at +inf, where every
    compare-exchange reaching past n leaves both in place and is dropped (103 for n = 20).
    Branch-free, it made the kernel 0.83x at k = 20 and 0.52-0.68x at k = 350-1000 against
    ranking the targets (O(k^2)): docs/performance.md, "The targets' sort"."""
    size, bits = 1, 0
    while size < n:
        size *= 2
        bits += 1
    most = size * bits * bits // 4 + 1  # (bits^2 - bits + 4) 2^(bits - 2) - 1 at most
    low = np.empty(most, np.int64)
    high = np.empty(most, np.int64)
    count = 0
    p = 1
    while p < size:
        step = p
        while step >= 1:
            for j in range(step % p, size - step, 2 * step):
                for i in range(min(step, size - j - step)):
                    a, b = i + j, i + j + step
                    if a // (2 * p) == b // (2 * p) and b < n:
                        low[count], high[count] = a, b
                        count += 1
            step //= 2
        p *= 2
    return low[:count], high[:count]


NEAR_TIE = 1e-9
"""Relative gap below which the k-th and the next trial of ``nearest_trials`` count as tied."""


@numba.njit(cache=True, nogil=True)
def nearest_trials(
    points: NDArray[np.float64], trials: NDArray[np.float64], order: NDArray[np.int64],
    leaf_start: NDArray[np.int64], leaf_box: NDArray[np.float64], k: int,
) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.bool_]]:  # pragma: no cover
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
    pos = np.zeros((n, n_groups, k), np.int32)
    sure = np.ones(n, np.bool_)
    near_s = np.empty(k + 1)
    near_t = np.empty(k + 1, np.int64)
    bound = np.empty(n_leaves)
    box_point = np.empty(n_params)
    for i in range(n):
        for g in range(n_groups):
            size = leaf_start[g, n_leaves]
            kk = min(k, size)
            keep = min(kk + 1, size)
            best_s, best_t = near_s[:keep], near_t[:keep]
            filled = 0
            limit = np.inf  # the (k + 1)-th nearest so far
            for leaf in range(n_leaves):
                bound[leaf] = _box_gap(leaf_box, g, leaf, points, i, n_params, box_point)
            while True:
                nearest = -1
                near = np.inf
                for leaf in range(n_leaves):
                    if bound[leaf] < near:
                        near = bound[leaf]
                        nearest = leaf
                if nearest < 0 or near > limit:
                    break  # every trial left is farther than the (k + 1)-th so far
                bound[nearest] = np.inf
                for t in range(leaf_start[g, nearest], leaf_start[g, nearest + 1]):
                    s = _sqeuclidean(trials, g, t, points, i, n_params)
                    if s >= limit:
                        continue
                    filled = _push(best_s, best_t, filled, s, t)
                    if filled == keep:
                        limit = best_s[keep - 1]
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
             i: int, n: int, near: NDArray[np.float64]) -> float:  # pragma: no cover - compiled
    """The squared distance of points[i] to the box leaf_box[g, leaf] (n coordinates; near (n,)
    scratch: the box's point nearest to it), summed as ``_sqeuclidean`` sums: no more than
    ``_sqeuclidean`` of any point in the box (every difference is at most that point's, and
    the sums are in the same order); inf for an empty box (lowest inf, highest -inf)."""
    for p in range(n):
        near[p] = min(max(points[i, p], leaf_box[g, leaf, 0, p]), leaf_box[g, leaf, 1, p])
    return _tree_sum(points[i], near, n)


@numba.njit(cache=True, nogil=True, inline="always")
def _sqeuclidean(trials: NDArray[np.float64], g: int, t: int, points: NDArray[np.float64],
                 i: int, n: int) -> float:  # pragma: no cover - compiled
    """|trials[g, t] - points[i]|^2 (n coordinates), as scipy's kd-tree sums it
    (``_tree_sum``)."""
    return _tree_sum(trials[g, t], points[i], n)


@numba.njit(cache=True, nogil=True, inline="always")
def _tree_sum(a: NDArray[np.float64], b: NDArray[np.float64],
              n: int) -> float:  # pragma: no cover - compiled
    """The sum of (a[p] - b[p])^2 over the first n coordinates in the order of scipy's kd-tree
    (``sqeuclidean_distance_double``): four partial sums over blocks of four coordinates, added
    in order, then the rest one by one (each difference taken where it is squared: a tenth
    faster than through a scratch array)."""
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    acc3 = 0.0
    p = 0
    while p + 4 <= n:
        d0 = a[p] - b[p]
        d1 = a[p + 1] - b[p + 1]
        d2 = a[p + 2] - b[p + 2]
        d3 = a[p + 3] - b[p + 3]
        acc0 += d0 * d0
        acc1 += d1 * d1
        acc2 += d2 * d2
        acc3 += d3 * d3
        p += 4
    s = acc0 + acc1 + acc2 + acc3
    while p < n:
        d = a[p] - b[p]
        s += d * d
        p += 1
    return s
