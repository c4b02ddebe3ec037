"""The numba kernel of the grouped kNN search (pipeline/surrogates/knn_search.py,
``TrialGroups``): the value of the k nearest rows of many query points (``knn_mean``).

Imported by the search on first use; without numba it uses ``knn_mean_numpy``, which gives the
same values (tests/test_knn_kernel.py compares both, ties included;
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
        di = pair_d[i]
        rank = 0
        same = 0
        for i2 in range(m):
            rank += pair_d[i2] < di
            same += pair_d[i2] == di
        if same > 1:  # ties: those gathered before it come first
            for i2 in range(i):
                rank += pair_d[i2] == di
        if rank < k:
            chosen[q] = rows_t[pair_row[i]]
            q += 1


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
                m = k - 1
                while m > 0 and best_d[m - 1] > d:
                    best_d[m] = best_d[m - 1]
                    best_row[m] = best_row[m - 1]
                    m -= 1
                best_d[m] = d
                best_row[m] = frame_row0[g, j] + trial_pos[g, a]


@numba.njit(cache=True, nogil=True, inline="always")
def _value(chosen: NDArray[np.float64], ordered: NDArray[np.float64], k: int,
           risk: float) -> float:  # pragma: no cover - compiled
    """``knn_search.canonical_value`` of the k targets chosen (k,): sorted ascending by their
    ranks into ordered (k,), summed left to right; mean (+ risk * population std)."""
    for i in range(k):
        v = chosen[i]
        rank = 0
        same = 0
        for i2 in range(k):
            rank += chosen[i2] < v
            same += chosen[i2] == v
        if same > 1:  # equal targets take the places after each other
            for i2 in range(i):
                rank += chosen[i2] == v
        ordered[rank] = v
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
