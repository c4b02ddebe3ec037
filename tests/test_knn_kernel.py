"""The numba kernels of the grouped kNN search (pipeline/surrogates/knn_kernel.py) give the
answers of the straightforward paths to the bit, ties included: ``knn_mean`` the stable order
of ``knn_mean_numpy``, ``nearest_trials`` the groups' kd-trees; and a selector on them makes the
choices of a selector on those paths (issue 33)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers.models import build_model

from pipeline.runtime import Model, Selector, load_model
from pipeline.selection import SelectionSettings
from pipeline.surrogates import knn_search
from pipeline.surrogates.knn import KnnSurrogate
from pipeline.surrogates.knn_kernel import _sorting_network, knn_mean
from pipeline.surrogates.knn_search import TrialGroups, knn_mean_numpy


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
    trial_pos = rng.integers(0, 50, (n, groups, k)).astype(np.int32)
    frame_row0 = rng.integers(0, 3900, (groups, k))
    return trial_d2, trial_pos, frame_d2, frame_row0, rows_t


@pytest.mark.parametrize("risk", [0.0, 0.5])
def test_knn_mean_is_the_stable_order_of_the_pairs(risk: float) -> None:
    """Random cases, most of them full of equal distances: the same bits as the numpy path's
    stable sort (the k first pairs by distance, then group, trial, frame), including points
    whose pairs all tie (every distance equal) and points with no bound (no group has k
    rows)."""
    rng = np.random.default_rng(7)
    for case in range(120):
        k = int(rng.choice([1, 2, 3, 5, 8, 20, 33]))
        args = kernel_case(rng, 30, int(rng.integers(1, 9)), k, int(rng.choice([2, 3, 10, 10**6])))
        if case % 10 == 0:  # every pair at distance 0: the order alone decides
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


def apply_network(n: int, values: np.ndarray) -> np.ndarray:
    """The compare-exchanges of ``_sorting_network(n)`` applied to every row of values (m, n)."""
    out = values.copy()
    for a, b in zip(*_sorting_network(n), strict=True):
        out[:, a], out[:, b] = np.minimum(out[:, a], out[:, b]), np.maximum(out[:, a], out[:, b])
    return out


def test_the_sorting_network_sorts_any_values() -> None:
    """Every 0-1 sequence of up to 14 values is sorted, which proves the network sorts any
    values of that length (Knuth's 0-1 principle); random values with ties for the lengths of
    the kernel's k past that."""
    for n in range(1, 15):
        zero_one = (np.arange(2**n)[:, None] >> np.arange(n)) & 1
        assert np.array_equal(apply_network(n, zero_one), np.sort(zero_one, axis=1)), n
    rng = np.random.default_rng(3)
    for n in (20, 33, 100, 350, 1000):
        values = rng.integers(0, 9, (50, n)) * 0.5
        assert np.array_equal(apply_network(n, values), np.sort(values, axis=1)), n


def random_knn(rng: np.random.Generator, n_params: int, grid: int | None, k: int = 5,
               groups: int = 3, frames: int = 4, trials: int = 40) -> KnnSurrogate:
    """A kNN surrogate of ``groups`` sequences whose frames share their sequence's trial
    vectors: uniform in [0, 1], or on a grid of ``grid`` values (ties and duplicates)."""
    blocks = [rng.integers(0, grid, (trials, n_params)) / (grid - 1) if grid
              else rng.random((trials, n_params)) for _ in range(groups)]
    rows_x = np.vstack([b for b in blocks for _ in range(frames)])
    n_env = groups * frames
    offsets = np.arange(n_env + 1, dtype=np.int64) * trials
    return KnnSurrogate(k, "log", rng.random((n_env, 3)), offsets, rows_x,
                        rng.random(len(rows_x)))


@pytest.mark.parametrize(("n_params", "grid"),
                         [(2, None), (3, None), (5, None), (2, 20), (3, 6), (5, 4)])
def test_nearest_trials_are_the_trees_answer(n_params: int, grid: int | None) -> None:
    """The search of the leaves gives the kd-trees' distances and positions to the bit
    (P = 5: the tree's four partial sums), sure of most points off the grid, not of points
    with tied trials (on a grid), which the trees then answer."""
    rng = np.random.default_rng(n_params)
    model = random_knn(rng, n_params, grid)
    groups = TrialGroups.build(model, rng.random((10, n_params)), 1.7)
    assert groups is not None and groups.compiled
    points = rng.random((300, n_params))
    if grid:
        points[::2] = rng.integers(0, grid, (150, n_params)) / (grid - 1)
    q = np.ascontiguousarray(points * groups.x_scale)
    tree = groups._tree_trials(q)
    _, _, sure = groups.leaves.nearest(q, groups.k)
    assert sure.mean() > 0.95 if grid is None else 0 < sure.mean() < 1
    for batch in (q[:1], q[:18], q[:64]):
        got = groups._leaf_trials(np.ascontiguousarray(batch))
        assert got[0].tobytes() == tree[0][: len(batch)].tobytes()
        assert got[1].tobytes() == tree[1][: len(batch)].tobytes()


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Model:
    return load_model(build_model(tmp_path_factory.mktemp("m") / "model", kitti_root))


def on_grid(model: Model, seed: int, grid: int) -> Model:
    """``model`` with a random surrogate of the same frames: each sequence's trial vectors
    drawn on a grid of ``grid`` values per parameter (duplicates, equal distances), targets
    on 8 values (equal values), k = 7."""
    knn = model.surrogate
    assert isinstance(knn, KnnSurrogate)
    rng = np.random.default_rng(seed)
    counts = np.diff(knn.env_offsets)
    rows_x = knn.rows_x.copy()
    for g in range(0, len(counts), 10):  # the test model: 10 frames a sequence
        block = rng.integers(0, grid, (counts[g], rows_x.shape[1])) / (grid - 1) * model.x_scale
        for f in range(g, g + 10):
            rows_x[knn.env_offsets[f] : knn.env_offsets[f + 1]] = block
    rows_t = rng.integers(0, 8, len(rows_x)) * 0.125
    return replace(model, surrogate=replace(knn, k=7, rows_x=rows_x, rows_t=rows_t))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_fast_paths_choose_as_the_straightforward_ones(
    model: Model, seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Random surrogates full of ties, the default pattern search, windows of 1 and 5 scans,
    risk 0 and 0.5: every selection (parameters and predicted value, to the bit) of the
    selector on the kernels is that of a selector on the numpy kNN and the kd-trees that finds
    the probes' nearest trials for every scan."""
    rng = np.random.default_rng(seed)
    tied = on_grid(model, seed, grid=5)
    envs = np.vstack([tied.env, tied.env[rng.integers(0, len(tied.env), 30)]
                      + rng.normal(0, 0.5, (30, tied.env.shape[1]))])
    for settings in (SelectionSettings(hysteresis=0.0),
                     SelectionSettings(hysteresis=0.0, window=1, risk=0.5),
                     SelectionSettings(risk=0.5, refine_iters=8)):
        choices = []
        for fast in (True, False):
            sel = Selector(tied, settings)
            sel.novelty_distance = float("inf")
            groups = sel.search.groups
            assert groups is not None and groups.compiled
            if not fast:
                groups.compiled = groups.reuse = sel.reuse = False
                monkeypatch.setattr(knn_search, "_knn_mean_kernel", lambda: knn_mean_numpy)
            picks = []
            for e in envs:
                params = sel.select_environment(e)
                picks.append([*params.values(), sel.last["predicted_t"]])
            monkeypatch.undo()
            choices.append(np.array(picks))
        assert choices[0].tobytes() == choices[1].tobytes(), settings
        assert len(np.unique(choices[0][:, :-1], axis=0)) > 3  # it does choose
