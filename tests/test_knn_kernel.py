"""The numba kernel of the grouped kNN search (pipeline/surrogates/knn_kernel.py) gives the
answers of the straightforward path to the bit, ties included: ``knn_mean`` the stable order
of ``knn_mean_numpy`` (issue 33)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.surrogates.knn_kernel import knn_mean
from pipeline.surrogates.knn_search import knn_mean_numpy


def kernel_case(rng: np.random.Generator, n: int, groups: int, k: int,
                levels: int) -> tuple[np.ndarray, ...]:
    """Arguments of ``knn_mean`` with distances on ``levels`` values (few levels: many ties),
    some groups with fewer than k trials or frames (inf padding), targets with ties."""
    trial_d2 = np.sort(rng.integers(0, levels, (n, groups, k)).astype(float), axis=2)
    frame_d2 = np.sort(rng.integers(0, levels, (groups, k)).astype(float), axis=1)
    for g in range(1, groups):  # group 0 stays full: k rows at least
        if rng.random() < 0.3:
            trial_d2[:, g, rng.integers(1, k + 1):] = np.inf
        if rng.random() < 0.3:
            frame_d2[g, rng.integers(1, k + 1):] = np.inf
    rows_t = rng.integers(0, 7, 4000) * 0.25
    trial_pos = rng.integers(0, 50, (n, groups, k))
    frame_row0 = rng.integers(0, 3900, (groups, k))
    return trial_d2, trial_pos, frame_d2, frame_row0, rows_t


@pytest.mark.parametrize("risk", [0.0, 0.5])
def test_knn_mean_is_the_stable_order_of_the_pairs(risk: float) -> None:
    """Random cases, most of them full of equal distances: the same bits as the numpy path's
    stable sort (the k first pairs by distance, then group, trial, frame), including points
    whose pairs within the bound overflow the buffer (every distance equal) and points with
    no bound (no group has k rows)."""
    rng = np.random.default_rng(7)
    for case in range(120):
        k = int(rng.choice([1, 2, 3, 5, 8, 20]))
        args = kernel_case(rng, 30, int(rng.integers(1, 9)), k, int(rng.choice([2, 3, 10, 10**6])))
        if case % 10 == 0:  # every pair at distance 0: the merge path
            args[0][:] = np.where(np.isfinite(args[0]), 0.0, np.inf)
            args[2][:] = np.where(np.isfinite(args[2]), 0.0, np.inf)
        fast, reference = knn_mean(*args, k, risk), knn_mean_numpy(*args, k, risk)
        assert fast.tobytes() == reference.tobytes(), case
    # 8 groups of 2 trials x 2 frames, k = 20: no corner of a group holds 10 rows
    trial_d2, trial_pos, frame_d2, frame_row0, rows_t = kernel_case(rng, 30, 8, 20, 5)
    trial_d2[:, :, 2:] = np.inf
    frame_d2[:, 2:] = np.inf
    args = (trial_d2, trial_pos, frame_d2, frame_row0, rows_t)
    assert knn_mean(*args, 20, risk).tobytes() == knn_mean_numpy(*args, 20, risk).tobytes()
