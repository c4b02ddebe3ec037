"""The k-nearest-neighbour surrogate (the paper's): S(E_s, X_s) = the mean target t of the k
training rows nearest to [E_s, X_s], Euclidean, uniform weights. The default surrogate.

The artifact keeps every training row, grouped by frame (env_offsets.npy, rows_x.npy,
rows_t.npy); the selector searches them exactly (``pipeline.surrogates.knn_search``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.surrogates.base import (
    Arrays,
    ArraySpec,
    Query,
    Regressor,
    TrainingSet,
    environment_d2,
)
from pipeline.surrogates.knn_search import (
    GroupedNeighbourhood,
    Neighbourhood,
    TrialGroups,
    canonical_mean,
)

if TYPE_CHECKING:
    from pipeline.surrogates.section import SurrogateSection


def check_k(k: object, rows: int, what: str, error: type[Exception] = ValueError) -> int:
    """``k`` when it is an integer in [1, ``rows``] (a mean of k of the rows); ``error``
    naming ``what`` otherwise."""
    if not isinstance(k, int) or isinstance(k, bool) or not 1 <= k <= rows:
        raise error(f"{what} must be an integer in [1, {rows}] (the training rows), got {k!r}")
    return k


@dataclass
class KnnSurrogate:
    """k and the training rows: env (n_env, D) E_s, env_offsets (n_env + 1,) the rows of each
    frame, rows_x (M, P) X_s, rows_t (M,) t (``TrainingSet``)."""

    type: ClassVar[str] = "knn"
    risk_aware: ClassVar[bool] = True  # its search weighs the neighbours' spread (``risk``)
    files: ClassVar[dict[str, ArraySpec]] = {
        "env_offsets.npy": ArraySpec(1, "i"),
        "rows_x.npy": ArraySpec(2),
        "rows_t.npy": ArraySpec(1),
    }
    manifest_schema: ClassVar[dict[str, Any]] = {
        "required": ["k"],
        "properties": {"k": {"type": "integer", "minimum": 1}, "weights": {"const": "uniform"},
                       "metric": {"const": "euclidean"}}}

    k: int
    target: str
    env: NDArray[np.float64]
    env_offsets: NDArray[np.int64]
    rows_x: NDArray[np.float64]
    rows_t: NDArray[np.float64]

    @classmethod
    def fit(cls, training: TrainingSet, section: SurrogateSection) -> KnnSurrogate:
        """Nothing to fit: the rows are the model. ConfigError when ``surrogate.k`` exceeds
        them (the artifact's loader would refuse the model)."""
        check_k(section.k, len(training.rows_t), "surrogate.k", ConfigError)
        return cls(section.k, section.target, training.env, training.env_offsets,
                   training.rows_x, training.rows_t)

    @classmethod
    def regressor(cls, section: SurrogateSection, n_params: int) -> Regressor:
        return GroupedKnnRegressor(section.k, n_params)

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """Exact kNN mean over every row (a kd-tree of the joint features): (n,)."""
        from scipy.spatial import cKDTree

        joint = TrainingSet(self.env, self.env_offsets, self.rows_x, self.rows_t).features()
        k = min(self.k, len(self.rows_t))
        _, idx = cKDTree(joint).query(np.atleast_2d(features), k=k)
        return canonical_mean(self.rows_t[np.reshape(idx, (len(idx), k))])

    def arrays(self) -> Arrays:
        return {"env_offsets.npy": self.env_offsets, "rows_x.npy": self.rows_x,
                "rows_t.npy": self.rows_t}

    def to_json(self) -> dict[str, Any]:
        return {"type": self.type, "k": self.k, "weights": "uniform", "metric": "euclidean",
                "target": self.target}

    @classmethod
    def from_artifact(cls, model: Mapping[str, Any], arrays: Arrays) -> KnnSurrogate:
        env = arrays["env.npy"]
        offsets = arrays["env_offsets.npy"]
        rows_x, rows_t = arrays["rows_x.npy"], arrays["rows_t.npy"]
        k = check_k(model.get("k"), len(rows_t), "model.k")
        if (offsets.shape != (len(env) + 1,) or offsets[0] != 0 or offsets[-1] != len(rows_t)
                or np.any(np.diff(offsets) < 0)):
            raise ValueError("env_offsets.npy: does not partition the rows into the frames")
        p = arrays["candidates.npy"].shape[1]
        if rows_x.shape != (len(rows_t), p):
            raise ValueError(f"rows_x.npy: shape {rows_x.shape}, expected ({len(rows_t)}, {p}) "
                             "(rows, parameters)")
        return cls(k, str(model.get("target", "log")), env, offsets.astype(np.int64), rows_x,
                   rows_t)

    def search(self, candidates_u: NDArray[np.float64], x_scale: float,
               options: Mapping[str, Any]) -> KnnSearch:
        return KnnSearch(self, candidates_u, x_scale, int(options.get("subset_rows", 4096)),
                         bool(options.get("grouped", True)), float(options.get("risk", 0.0)))


class GroupedKnnRegressor:
    """The kNN mean over flat rows [E_s, X_s] (the cross-validation's view), searched as the
    selector searches: exactly, by frame groups (``pipeline.surrogates.knn_search``).

    ``fit`` groups the rows into frames (rows with the same E_s, in row order within a frame)
    and the frames into groups sharing one block of trial vectors; ``predict`` answers all
    queries of one E_s at once. Training rows that do not group (more than ``MAX_GROUPS``
    blocks, as pruned trials give) are searched by scikit-learn's kd-tree instead. Both give
    the Euclidean kNN mean of the k nearest rows (ties at the k-th distance aside).
    """

    def __init__(self, k: int, n_params: int) -> None:
        self.k = k
        self.n_params = n_params
        self.groups: TrialGroups | None = None
        self.fallback: Regressor | None = None

    def fit(self, features: NDArray[np.float64], t: NDArray[np.float64]) -> GroupedKnnRegressor:
        """Fit on (M, D + P) rows and their (M,) targets; returns itself."""
        d = features.shape[1] - self.n_params
        env, order, offsets = _by_environment(features[:, :d])
        model = KnnSurrogate(min(self.k, len(t)), "log", env, offsets, features[order, d:],
                             t[order])
        self.groups = TrialGroups.build(model, features[:1, d:], 1.0)
        if self.groups is None:
            from sklearn.neighbors import KNeighborsRegressor

            self.fallback = KNeighborsRegressor(n_neighbors=self.k).fit(features, t)
        return self

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, D + P) rows -> (n,) kNN mean targets."""
        if self.fallback is not None:
            return np.asarray(self.fallback.predict(features), np.float64)
        assert self.groups is not None, "fit first"
        d = features.shape[1] - self.n_params
        out = np.empty(len(features))
        queries, order, offsets = _by_environment(features[:, :d])
        for e_s, rows in zip(queries, np.split(order, offsets[1:-1]), strict=True):
            env_d2 = environment_d2(self.groups.model.env, e_s)
            out[rows] = GroupedNeighbourhood(self.groups, env_d2).predict(features[rows, d:]).t
        return out


def _by_environment(
    E: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.int64]]:
    """Rows grouped by equal environment E (M, D): the distinct environments (G, D), the row
    order that groups them (M,) (rows keep their order within a group) and the group
    offsets (G + 1,) into it."""
    env, which = np.unique(E, axis=0, return_inverse=True)
    which = which.reshape(-1)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(which, minlength=len(env)))])
    return env, np.argsort(which, kind="stable"), offsets.astype(np.int64)


class KnnSearch:
    """The exact grouped search when the frames group, else the certified kd-tree; both give
    mean + risk * std of the k neighbours' targets (``knn_search.canonical_value``)."""

    def __init__(self, model: KnnSurrogate, candidates_u: NDArray[np.float64], x_scale: float,
                 subset_rows: int, grouped: bool = True, risk: float = 0.0) -> None:
        self.model = model
        self.x_scale = x_scale
        self.subset_rows = subset_rows
        self.risk = risk
        self.groups = TrialGroups.build(model, candidates_u, x_scale) if grouped else None

    def at(self, e_s: NDArray[np.float64], env_d2: NDArray[np.float64]) -> Query:
        if self.groups is not None:
            return GroupedNeighbourhood(self.groups, env_d2, self.risk)
        return Neighbourhood(self.model, env_d2, self.subset_rows, self.x_scale, self.risk)
