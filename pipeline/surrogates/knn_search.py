"""The kNN surrogate's search: the k nearest training rows of (E_s, x) for many x at once.

Since E_s is fixed for a query, the joint distance of a row i to (E_s, x) is
|x - x_i|^2 + dE_i^2 with dE_i = |E_s - E_i|: the joint kNN is a kNN in P + 1 dimensions over
the points (x_i, dE_i), queried at (x, 0).

Exact over every row, grouped (``TrialGroups``, ``GroupedNeighbourhood``): every frame of a
training sequence has one row per trial of that sequence, the same parameter vectors in the
same order, so the frames fall into a few groups (one per sequence) that share a block X_g of
trial vectors. The k nearest rows of (E_s, x) are among the pairs (one of the k nearest trials
of x in X_g, one of the k nearest frames of E_s in group g): any other row is farther than k
rows of the same frame (nearer trials) or of the same trial (nearer frames). The nearest trials
of the candidate set are static (found once per selector); per selection only the k nearest
frames of each group are found and the k nearest pairs picked, ties by (group, trial, frame)
(``pipeline.surrogates.knn_kernel.knn_mean`` in numba, ``knn_mean_numpy``'s stable sort
without numba: the same bits). The nearest trials of the few points of a pattern-search round
are found in numba too (``TrialLeaves``, ``knn_kernel.nearest_trials``), exactly as the
groups' kd-trees find them, which answer whenever that is not sure (ties).

Risk (the selector's ``risk`` >= 0, pipeline/runtime.py): every search gives the value
mean + risk * std of the k neighbours' targets (population std), ``canonical_value``; risk 0 is
the plain kNN mean, to the last bit.

Certified (``Neighbourhood``), for an artifact whose frames do not form at most ``MAX_GROUPS``
groups: the frames nearest to E_s are taken until ``subset_rows`` rows are gathered, a cKDTree
over those rows' (x_i, dE_i) answers the k nearest rows, and a value is *certified exact* when
its k-th neighbour distance is <= the E-distance of the first frame left out (every left-out
row is at least that far), so it equals the kNN over all rows; ``Prediction.exact`` says which,
and the search uses certified values only (the tree is searched within that distance,
``Neighbourhood.certified``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Protocol, TypeAlias

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pipeline.surrogates.base import Prediction


class KnnRows(Protocol):
    """What the searches read of a kNN surrogate (``pipeline.surrogates.knn.KnnSurrogate``):
    k, env (n_env, D) E_s of the training frames, env_offsets (n_env + 1,) the rows of each,
    rows_x (M, P) X_s and rows_t (M,) their targets."""

    k: int
    env: NDArray[np.float64]
    env_offsets: NDArray[np.int64]
    rows_x: NDArray[np.float64]
    rows_t: NDArray[np.float64]


class Neighbourhood:
    """The rows near one environment E_s, as a (P + 1)-D tree (module docstring: the certified
    search)."""

    def __init__(self, model: KnnRows, d2: NDArray[np.float64], subset_rows: int,
                 x_scale: float, risk: float = 0.0) -> None:
        """d2 (n_env,): squared E-distances of the training frames to E_s; risk: the weight of
        the neighbours' spread (``canonical_value``)."""
        counts = np.diff(model.env_offsets)
        n_env = len(d2)
        order = np.argsort(d2)
        cum = np.cumsum(counts[order])
        n_take = min(int(np.searchsorted(cum, max(subset_rows, model.k))) + 1, n_env)
        taken = order[:n_take]
        self.boundary2 = float(d2[order[n_take]]) if n_take < n_env else math.inf
        lens = counts[taken]
        starts = model.env_offsets[taken]
        total = int(lens.sum())
        shift = np.repeat(starts - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens)
        self.rows = shift + np.arange(total)
        self.rows_searched = total
        self.k = min(model.k, total)
        pts = np.empty((total, model.rows_x.shape[1] + 1))
        pts[:, :-1] = model.rows_x[self.rows]
        pts[:, -1] = np.repeat(np.sqrt(d2[taken]), lens)
        self.t = model.rows_t[self.rows]
        # built for every selection and queried ~3000 times: the sliding-midpoint tree builds
        # in half the time of the balanced one and queries as fast (make bench)
        self.tree = cKDTree(pts, leafsize=32, balanced_tree=False, compact_nodes=False)
        self.x_scale = x_scale
        self.risk = risk

    def predict(self, U: NDArray[np.float64]) -> Prediction:
        """Prediction at unit points U (C, P)."""
        dist, idx = self._query(U, math.inf)
        return Prediction(canonical_value(self.t[idx], self.risk),
                          dist[:, -1] ** 2 <= self.boundary2)

    def certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """``predict(U).t`` where it is certified exact, inf elsewhere: (C,).

        The tree is searched only within the certification distance (inf: no bound), which
        prunes more of it than ``predict``."""
        dist, idx = self._query(U, math.sqrt(self.boundary2) * (1.0 + 1e-9) + 1e-12)
        exact = dist[:, -1] ** 2 <= self.boundary2
        t = np.full(len(U), np.inf)
        t[exact] = canonical_value(self.t[idx[exact]], self.risk)
        return t

    def candidate_values(self, candidates: NDArray[np.float64]) -> NDArray[np.float64]:
        """``certified`` at the selector's candidate set."""
        return self.certified(candidates)

    def _query(
        self, U: NDArray[np.float64], bound: float
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Distances and row indices (C, k) of the k nearest rows to (U * x_scale, 0) within
        ``bound`` (inf and len(rows) past it)."""
        q = np.zeros((len(U), U.shape[1] + 1))
        q[:, :-1] = U * self.x_scale
        dist, idx = self.tree.query(q, k=self.k, distance_upper_bound=bound)
        if self.k == 1:
            dist, idx = dist[:, None], idx[:, None]
        return dist, idx


MAX_GROUPS = 64  # beyond this many frame groups the search uses Neighbourhood
LEAF_POINTS = 64
"""``TrialGroups.nearest_trials`` of at most this many points (the pattern search's probes)
searches the leaves (``knn_kernel.nearest_trials``): a kd-tree query costs about 35 us a call
and group before it searches anything. More points (the candidates, the cross-validation's
rows) ask the trees."""
LEAF_TRIALS = 16
"""The most trial vectors in one leaf of ``TrialLeaves``."""


class TrialLeaves:
    """Each group's trial vectors in leaves of at most LEAF_TRIALS, split at the median of
    their widest coordinate, with the box around each leaf: what ``knn_kernel.nearest_trials``
    searches. trials (G, T, P) leaf by leaf (zero-padded), order (G, T) their positions in the
    group's block, starts (G, L + 1), boxes (G, L, 2, P) (lowest, highest; empty: inf, -inf).
    """

    def __init__(self, block_x: list[NDArray[np.float64]]) -> None:
        """block_x: each group's trial vectors (T_g, P), in block order."""
        leaves = [_split(x, np.arange(len(x))) for x in block_x]
        n_leaves = max(map(len, leaves))
        n_params = block_x[0].shape[1]
        self.trials = np.zeros((len(block_x), max(map(len, block_x)), n_params))
        self.order = np.zeros(self.trials.shape[:2], np.int64)
        self.starts = np.zeros((len(block_x), n_leaves + 1), np.int64)
        self.boxes = np.empty((len(block_x), n_leaves, 2, n_params))
        self.boxes[:, :, 0], self.boxes[:, :, 1] = np.inf, -np.inf
        for g, (x, parts) in enumerate(zip(block_x, leaves, strict=True)):
            order = np.concatenate(parts)
            self.order[g, : len(x)] = order
            self.trials[g, : len(x)] = x[order]
            self.starts[g, 1:] = len(x)
            self.starts[g, 1 : len(parts) + 1] = np.cumsum([len(p) for p in parts])
            for leaf, part in enumerate(parts):
                self.boxes[g, leaf] = x[part].min(axis=0), x[part].max(axis=0)

    def nearest(
        self, q: NDArray[np.float64], k: int
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
        """``knn_kernel.nearest_trials`` of the scaled points q (n, P), C-contiguous."""
        from pipeline.surrogates.knn_kernel import nearest_trials

        return nearest_trials(q, self.trials, self.order, self.starts, self.boxes, k)


def _split(x: NDArray[np.float64], idx: NDArray[np.intp]) -> list[NDArray[np.intp]]:
    """The positions idx of trial vectors x (T, P) in leaves of at most LEAF_TRIALS: halves at
    the median of the widest coordinate, recursively."""
    if len(idx) <= LEAF_TRIALS:
        return [idx]
    dim = int(np.argmax(np.ptp(x[idx], axis=0)))
    idx = idx[np.argsort(x[idx, dim], kind="stable")]
    half = len(idx) // 2
    return _split(x, idx[:half]) + _split(x, idx[half:])


class TrialGroups:
    """The rows as groups of frames sharing one block of trial vectors (module docstring), with
    the k nearest trials of every candidate. Built once per Selector."""

    def __init__(
        self, model: KnnRows, blocks: list[list[int]], candidates_u: NDArray[np.float64],
        x_scale: float,
    ) -> None:
        """``blocks``: the frames of each group (frames whose rows hold the same trial vectors
        in the same order); candidates_u (C, P): the selector's candidate set."""
        offsets = model.env_offsets
        self.model = model
        self.k = model.k
        self.x_scale = x_scale
        block_x = [model.rows_x[offsets[f[0]] : offsets[f[0] + 1]] for f in blocks]
        self.trees = [cKDTree(x) for x in block_x]
        self.frame_table = np.full((len(blocks), max(map(len, blocks))), -1, np.int64)  # (G, F)
        for g, frames in enumerate(blocks):
            self.frame_table[g, : len(frames)] = frames
        self.leaves = TrialLeaves(block_x)
        self.candidates = candidates_u
        self.reuse = True
        self._last: tuple[bytes, tuple[NDArray[np.float64], NDArray[np.int64]]] | None = None
        self.compiled = False  # the trees, until the leaves are seen to agree with them
        self.candidate_trials = self.nearest_trials(candidates_u)
        self.compiled = self._leaves_agree(candidates_u)

    @classmethod
    def build(cls, model: KnnRows, candidates_u: NDArray[np.float64],
              x_scale: float) -> TrialGroups | None:
        """The groups of ``model``, or None when its frames form more than MAX_GROUPS groups
        (or it has fewer than k rows)."""
        if len(model.rows_t) < model.k:
            return None
        offsets = model.env_offsets
        blocks: dict[bytes, list[int]] = {}
        for f in range(len(offsets) - 1):
            key = model.rows_x[offsets[f] : offsets[f + 1]].tobytes()
            blocks.setdefault(key, []).append(f)
            if len(blocks) > MAX_GROUPS:
                return None
        return cls(model, list(blocks.values()), candidates_u, x_scale)

    def nearest_trials(
        self, U: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Squared distances and block positions (n, G, k) of the k nearest trial vectors of
        each unit point U (n, P) in every group (ascending; inf and 0 past a group's size);
        read-only.

        They do not depend on the environment: a selector over a window of W scans asks for
        the same points under each of them (the pattern search's probes, the parameters in
        force), so the last answer is kept and given again for the same U (``reuse``; off, it
        is computed every time: the same arrays). A few points are searched in the leaves
        (``compiled``, LEAF_POINTS; off: the trees, the same arrays)."""
        key = np.ascontiguousarray(U, np.float64).tobytes()  # P is fixed: the bytes give n
        if self.reuse and self._last is not None and self._last[0] == key:
            return self._last[1]
        q = np.ascontiguousarray(U * self.x_scale, np.float64)
        if self.compiled and len(q) <= LEAF_POINTS:
            d2, pos = self._leaf_trials(q)
        else:
            d2, pos = self._tree_trials(q)
        d2.flags.writeable = pos.flags.writeable = False
        self._last = (key, (d2, pos))
        return d2, pos

    def _tree_trials(
        self, q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``nearest_trials`` of the scaled points q (n, P) by the groups' kd-trees."""
        n = len(q)
        d2 = np.full((n, len(self.trees), self.k), np.inf)
        pos = np.zeros((n, len(self.trees), self.k), np.int64)
        for g, tree in enumerate(self.trees):
            kk = min(self.k, tree.n)
            dist, idx = tree.query(q, k=kk)
            d2[:, g, :kk] = np.reshape(dist, (n, kk)) ** 2
            pos[:, g, :kk] = np.reshape(idx, (n, kk))
        return d2, pos

    def _leaf_trials(
        self, q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``nearest_trials`` of the scaled points q (n, P) by the leaves
        (``knn_kernel.nearest_trials``), the trees' answer for the points it is not sure of
        (ties)."""
        d2, pos, sure = self.leaves.nearest(q, self.k)
        if not sure.all():
            d2[~sure], pos[~sure] = self._tree_trials(q[~sure])
        return d2, pos

    def _leaves_agree(self, candidates_u: NDArray[np.float64]) -> bool:
        """True when numba is there and ``knn_kernel.nearest_trials`` gives the trees' answer
        to the bit at the first 256 candidates (``candidate_trials``) and at 256 random points,
        where it is sure: its sums are the trees' (a scipy built to fuse multiply-adds would
        differ)."""
        try:
            import pipeline.surrogates.knn_kernel  # noqa: F401
        except ImportError:  # pragma: no cover - numba is a dependency of the pipeline
            return False
        random_q = np.random.default_rng(0).random((256, candidates_u.shape[1])) * self.x_scale
        agree = True
        for q, (tree_d2, tree_pos) in (
            (candidates_u[:256] * self.x_scale, [a[:256] for a in self.candidate_trials]),
            (random_q, self._tree_trials(random_q)),
        ):
            d2, pos, sure = self.leaves.nearest(np.ascontiguousarray(q, np.float64), self.k)
            agree &= np.array_equal(d2[sure], tree_d2[sure])
            agree &= np.array_equal(pos[sure], tree_pos[sure])
        return bool(agree)

    def nearest_frames(
        self, env_d2: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Squared E-distances and first rows (G, k) of each group's k nearest frames, given
        every frame's squared E-distance env_d2 (n_env,) (ascending; inf and 0 past a group's
        size)."""
        table = self.frame_table
        d2 = np.where(table >= 0, env_d2[table], np.inf)
        kk = min(self.k, table.shape[1])
        pick = np.argpartition(d2, kk - 1, axis=1)[:, :kk] if table.shape[1] > kk else None
        if pick is not None:
            d2, table = np.take_along_axis(d2, pick, 1), np.take_along_axis(table, pick, 1)
        order = np.argsort(d2, axis=1, kind="stable")
        frame_d2 = np.full((len(table), self.k), np.inf)
        frame_row0 = np.zeros((len(table), self.k), np.int64)
        frame_d2[:, :kk] = np.take_along_axis(d2, order, 1)
        frames = np.maximum(np.take_along_axis(table, order, 1), 0)  # padding -> frame 0
        frame_row0[:, :kk] = self.model.env_offsets[frames]
        return frame_d2, frame_row0


class GroupedNeighbourhood:
    """TrialGroups at one environment E_s: the exact kNN over every row."""

    def __init__(self, groups: TrialGroups, env_d2: NDArray[np.float64],
                 risk: float = 0.0) -> None:
        """env_d2 (n_env,): squared E-distances of the training frames to E_s; risk: the
        weight of the neighbours' spread (``canonical_value``)."""
        self.groups = groups
        self.risk = risk
        self.frame_d2, self.frame_row0 = groups.nearest_frames(env_d2)
        self.rows_searched = len(groups.model.rows_t)  # all of them

    def predict(self, U: NDArray[np.float64]) -> Prediction:
        """Prediction at unit points U (C, P), every value exact."""
        t = self._mean(*self.groups.nearest_trials(U))
        return Prediction(t, np.ones(len(t), bool))

    def certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """``predict(U).t`` (every value is exact): (C,)."""
        return self.predict(U).t

    def candidate_values(self, candidates: NDArray[np.float64]) -> NDArray[np.float64]:
        """``certified`` at the groups' candidate set (their nearest trials are known)."""
        if candidates is not self.groups.candidates:
            return self.certified(candidates)
        return self._mean(*self.groups.candidate_trials)

    def _mean(
        self, trial_d2: NDArray[np.float64], trial_pos: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        return _knn_mean_kernel()(
            trial_d2, trial_pos, self.frame_d2, self.frame_row0, self.groups.model.rows_t,
            self.groups.k, self.risk,
        )


F64: TypeAlias = NDArray[np.float64]
I64: TypeAlias = NDArray[np.int64]


def knn_mean_numpy(
    trial_d2: F64, trial_pos: I64, frame_d2: F64, frame_row0: I64, rows_t: F64, k: int,
    risk: float = 0.0,
) -> F64:
    """``pipeline.surrogates.knn_kernel.knn_mean`` in numpy (same arguments, same values): (n,).

    The k nearest rows are the k first pairs (trial a, frame j of group g) by distance, ties
    by (g, a, j) (a stable sort of the pairs in that order). Only the pairs with
    (a + 1)(j + 1) <= k can be among them: a pair farther down both sorted lists comes after
    the (a + 1)(j + 1) - 1 pairs above and left of it.
    """
    a, j = np.array([(a, j) for a in range(k) for j in range(k) if (a + 1) * (j + 1) <= k]).T
    n = len(trial_d2)
    d2 = (trial_d2[:, :, a] + frame_d2[None, :, j]).reshape(n, -1)
    rows = (trial_pos[:, :, a] + frame_row0[None, :, j]).reshape(n, -1)
    pick = np.argsort(d2, axis=1, kind="stable")[:, :k]
    return canonical_value(rows_t[np.take_along_axis(rows, pick, 1)], risk)


def canonical_mean(t: F64) -> F64:
    """Mean of every row of t (n, k), summed in ascending order: (n,).

    A floating-point sum depends on its order, and the order in which a search finds the same k
    neighbours differs from one query point to the next (and between the numba and numpy
    searches). Candidates with the same neighbours then differed in their last bits, and the
    argmin among such equals was decided by rounding noise, which any last-digit change of the
    environment (another BLAS, another machine) could flip. Summed in ascending order, the same
    neighbours give the same bits; the selector breaks such exact ties by a rule of its own
    (pipeline/runtime.py, step 5). The sum runs left to right, one column at a time, as the numba
    kernel's loop does: numpy's own ``sum`` adds eight partial sums pairwise from eight values
    on, which gave other last bits than the kernel for k = 20.
    """
    return canonical_value(t, 0.0)


def canonical_value(t: F64, risk: float) -> F64:
    """mean + risk * std of every row of t (n, k) (population std): (n,), canonical as
    ``canonical_mean`` is (the same neighbours give the same bits, in any order).

    Both sums run over the ascending values, left to right: the mean m as ``canonical_mean``,
    then std = sqrt(sum((t_j - m) * (t_j - m)) / k), as the numba kernel's loops do. risk 0
    returns the mean itself (no std computed).
    """
    ordered = np.sort(t, axis=1)
    mean = _sum_columns(ordered) / t.shape[1]
    if risk == 0.0:
        return mean
    dev = ordered - mean[:, None]
    return mean + risk * np.sqrt(_sum_columns(dev * dev) / t.shape[1])


def _sum_columns(a: F64) -> F64:
    """Row sums of a (n, k), added left to right one column at a time: (n,)."""
    total = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        total += a[:, j]
    return total


KnnMean = Callable[..., NDArray[np.float64]]


@functools.cache
def _knn_mean_kernel() -> KnnMean:
    """``pipeline.surrogates.knn_kernel.knn_mean`` (numba), or ``knn_mean_numpy`` without
    numba."""
    try:
        from pipeline.surrogates.knn_kernel import knn_mean
    except ImportError:  # pragma: no cover - numba is a dependency of the pipeline, not the robot
        return knn_mean_numpy
    kernel: KnnMean = knn_mean
    return kernel


