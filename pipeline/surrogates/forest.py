"""A random-forest surrogate: S(E_s, X_s) = the mean over T regression trees of the mean target
of the leaf [E_s, X_s] falls into. A deliberately simple second implementation of the seam.

Fitted by scikit-learn's ``RandomForestRegressor`` (bootstrap samples of ``max_samples`` rows,
leaves of at least ``min_samples_leaf`` rows), then exported to plain arrays, every tree's nodes
one after the other: forest_feature.npy (N,) the split feature (-1 at a leaf),
forest_threshold.npy (N,), forest_left.npy / forest_right.npy (N,) the children's global node
indices (-1 at a leaf), forest_value.npy (N,) the node's mean target, forest_roots.npy (T,).
The runtime walks the trees with numpy: a sample goes left when its feature, rounded to float32
as scikit-learn does, is <= the threshold. No pickle: the arrays are the model.

Children always come after their parent (scikit-learn numbers nodes depth first; the loader
checks it), so a walk ends after at most the depth of the deepest tree.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.surrogates.base import (
    Arrays,
    ArraySpec,
    Prediction,
    Query,
    Regressor,
    TrainingSet,
)

if TYPE_CHECKING:
    from pipeline.surrogates.section import SurrogateSection


@dataclass
class ForestSurrogate:
    """The exported forest (module docstring): N nodes of T trees."""

    type: ClassVar[str] = "forest"
    risk_aware: ClassVar[bool] = False  # the spread of its trees is not the neighbours' spread
    files: ClassVar[dict[str, ArraySpec]] = {
        "forest_feature.npy": ArraySpec(1, "i"), "forest_threshold.npy": ArraySpec(1),
        "forest_left.npy": ArraySpec(1, "i"), "forest_right.npy": ArraySpec(1, "i"),
        "forest_value.npy": ArraySpec(1), "forest_roots.npy": ArraySpec(1, "i"),
    }
    manifest_schema: ClassVar[dict[str, Any]] = {
        "required": ["trees", "min_samples_leaf", "nodes"],
        "properties": {"trees": {"type": "integer", "minimum": 1},
                       "min_samples_leaf": {"type": "integer", "minimum": 1},
                       "max_samples": {"type": ["integer", "null"], "minimum": 1},
                       "nodes": {"type": "integer", "minimum": 1}}}

    feature: NDArray[np.int64]
    threshold: NDArray[np.float64]
    left: NDArray[np.int64]
    right: NDArray[np.int64]
    value: NDArray[np.float64]
    roots: NDArray[np.int64]
    settings: dict[str, Any]
    target: str = "log"

    @classmethod
    def fit(cls, training: TrainingSet, section: SurrogateSection) -> ForestSurrogate:
        forest = cls._estimator(section, len(training.rows_t))
        forest.fit(training.features(), training.rows_t)
        return cls.export(forest, section)

    @classmethod
    def _estimator(cls, section: SurrogateSection, rows: int | None = None) -> Any:
        from sklearn.ensemble import RandomForestRegressor

        f = section.forest
        max_samples = f.max_samples if rows is None or f.max_samples is None else min(
            f.max_samples, rows)
        return RandomForestRegressor(n_estimators=f.trees, min_samples_leaf=f.min_samples_leaf,
                                     max_samples=max_samples, random_state=section.seed)

    @classmethod
    def regressor(cls, section: SurrogateSection, n_params: int) -> Regressor:
        return _ForestRegressor(section)

    @classmethod
    def export(cls, forest: Any, section: SurrogateSection) -> ForestSurrogate:
        """The arrays of a fitted RandomForestRegressor."""
        parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("f", "th", "l", "r", "v")}
        roots, offset = [], 0
        for tree in (e.tree_ for e in forest.estimators_):
            leaf = tree.children_left < 0
            roots.append(offset)
            parts["f"].append(np.where(leaf, -1, tree.feature))
            parts["th"].append(np.where(leaf, 0.0, tree.threshold))
            parts["l"].append(np.where(leaf, -1, tree.children_left + offset))
            parts["r"].append(np.where(leaf, -1, tree.children_right + offset))
            parts["v"].append(tree.value[:, 0, 0])
            offset += tree.node_count
        cat = {k: np.concatenate(v) for k, v in parts.items()}
        f = section.forest
        return cls(cat["f"].astype(np.int64), cat["th"].astype(np.float64),
                   cat["l"].astype(np.int64), cat["r"].astype(np.int64),
                   cat["v"].astype(np.float64), np.array(roots, np.int64),
                   {"trees": f.trees, "min_samples_leaf": f.min_samples_leaf,
                    "max_samples": f.max_samples, "seed": section.seed}, section.target)

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """Mean leaf value over the trees at every row of (n, D + P) features: (n,)."""
        X = np.atleast_2d(np.asarray(features, np.float64)).astype(np.float32)
        node = np.broadcast_to(self.roots, (len(X), len(self.roots))).copy()
        rows = np.arange(len(X))[:, None]
        inner = self.feature[node] >= 0
        while inner.any():
            f = self.feature[node]
            go_left = X[rows, np.maximum(f, 0)] <= self.threshold[node]
            node = np.where(inner, np.where(go_left, self.left[node], self.right[node]), node)
            inner = self.feature[node] >= 0
        return np.asarray(self.value[node].mean(axis=1))

    def arrays(self) -> Arrays:
        return dict(zip(self.files, (self.feature, self.threshold, self.left, self.right,
                                     self.value, self.roots), strict=True))

    def to_json(self) -> dict[str, Any]:
        return {"type": self.type, **self.settings, "nodes": len(self.feature),
                "target": self.target}

    @classmethod
    def from_artifact(cls, model: Mapping[str, Any], arrays: Arrays) -> ForestSurrogate:
        feature, threshold, left, right, value, roots = (arrays[f] for f in cls.files)
        n = len(feature)
        for name, arr in zip(cls.files, (feature, threshold, left, right, value), strict=False):
            if len(arr) != n:
                raise ValueError(f"{name}: {len(arr)} nodes, forest_feature.npy has {n}")
        if not len(roots) or np.any((roots < 0) | (roots >= n)):
            raise ValueError("forest_roots.npy: must hold node indices")
        inner = feature >= 0
        idx = np.arange(n)
        width = arrays["env.npy"].shape[-1] + arrays["candidates.npy"].shape[-1]
        if np.any(feature >= width):
            raise ValueError(f"forest_feature.npy: features must be < {width}")
        for name, child in (("forest_left.npy", left), ("forest_right.npy", right)):
            if np.any(inner & ((child <= idx) | (child >= n))):
                raise ValueError(f"{name}: a child must come after its parent")
        return cls(feature.astype(np.int64), threshold.astype(np.float64),
                   left.astype(np.int64), right.astype(np.int64), value.astype(np.float64),
                   roots.astype(np.int64),
                   {k: v for k, v in model.items() if k not in ("type", "nodes", "target")},
                   str(model.get("target", "log")))

    def search(self, candidates_u: NDArray[np.float64], x_scale: float,
               options: Mapping[str, Any]) -> ForestSearch:
        return ForestSearch(self, x_scale)


class _ForestRegressor:
    """The cross-validation's forest: fitted and evaluated like the exported one."""

    def __init__(self, section: SurrogateSection) -> None:
        self.section = section
        self.model: ForestSurrogate | None = None

    def fit(self, features: NDArray[np.float64], t: NDArray[np.float64]) -> _ForestRegressor:
        forest = ForestSurrogate._estimator(self.section, len(t)).fit(features, t)
        self.model = ForestSurrogate.export(forest, self.section)
        return self

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        assert self.model is not None, "fit first"
        return self.model.predict(features)


class ForestSearch:
    """Queries of the forest: every prediction is exact (it searches nothing)."""

    def __init__(self, model: ForestSurrogate, x_scale: float) -> None:
        self.model = model
        self.x_scale = x_scale

    def at(self, e_s: NDArray[np.float64], env_d2: NDArray[np.float64]) -> Query:
        return ForestQuery(self.model, e_s, self.x_scale)


class ForestQuery:
    """The forest at one environment E_s."""

    def __init__(self, model: ForestSurrogate, e_s: NDArray[np.float64], x_scale: float) -> None:
        self.model, self.e_s, self.x_scale = model, e_s, x_scale
        self.rows_searched = 0

    def predict(self, U: NDArray[np.float64]) -> Prediction:
        feats = np.hstack([np.broadcast_to(self.e_s, (len(U), len(self.e_s))), U * self.x_scale])
        t = self.model.predict(feats)
        return Prediction(t, np.ones(len(t), bool))

    def certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.predict(U).t

    def candidate_values(self, candidates: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.certified(candidates)
