"""The merge kernel of the grouped kNN search before its bound-and-rank rewrite (issue 33,
main@6b0bde1: ``pipeline/surrogates/knn_kernel.py``): the pairs of each group merged in
(group, trial, frame) order into a sorted best list of k.

Kept here only as the same-run reference of bench_model.py (the selection the new kernels are
timed against, and must choose as). Not imported by the package.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray


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
    (M,) the targets. A row's squared joint distance is trial_d2 + frame_d2. Both lists are
    sorted, so a group is left as soon as its next pair cannot beat the k-th best so far.
    The value is ``knn_search.canonical_value`` of the k targets (the same bits for the same
    neighbours, whatever order they were found in): their mean, plus risk times their
    population std when risk > 0.
    """
    n, n_groups, width = trial_d2.shape
    out = np.empty(n)
    best_d = np.empty(k)
    best_r = np.empty(k, np.int64)
    ordered = np.empty(k)
    for c in range(n):
        best_d[:] = np.inf
        best_r[:] = 0
        for g in range(n_groups):
            for a in range(width):
                da = trial_d2[c, g, a]
                if da + frame_d2[g, 0] >= best_d[k - 1]:
                    break
                for j in range(frame_d2.shape[1]):
                    d = da + frame_d2[g, j]
                    if d >= best_d[k - 1]:
                        break
                    m = k - 1
                    while m > 0 and best_d[m - 1] > d:
                        best_d[m] = best_d[m - 1]
                        best_r[m] = best_r[m - 1]
                        m -= 1
                    best_d[m] = d
                    best_r[m] = frame_row0[g, j] + trial_pos[c, g, a]
        for m in range(k):  # the k targets in ascending order (canonical: see
            v = rows_t[best_r[m]]  # knn_search.canonical_value), by insertion: no allocation
            i = m
            while i > 0 and ordered[i - 1] > v:
                ordered[i] = ordered[i - 1]
                i -= 1
            ordered[i] = v
        total = 0.0
        for m in range(k):  # left to right, as canonical_value
            total += ordered[m]
        mean = total / k
        if risk == 0.0:
            out[c] = mean
            continue
        squares = 0.0
        for m in range(k):
            dev = ordered[m] - mean
            squares += dev * dev
        out[c] = mean + risk * np.sqrt(squares / k)
    return out
