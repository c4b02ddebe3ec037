"""The surrogate seam: what every surrogate S(E_s, X_s) ~ t implements (docs/design.md,
"Seams").

A surrogate is fitted on a ``TrainingSet`` (the training rows grouped by frame, already scaled:
E_s, X_s, target t), stores itself as plain arrays in the artifact, is rebuilt from them by the
runtime, and answers the selector's queries: for one scan's environment E_s, the predicted
target at many unit parameter points (``Search.at`` -> ``Query``). A ``Regressor`` of the same
kind, fitted and evaluated on flat feature rows, serves the leave-one-sequence-out
cross-validation. Implementations register in ``pipeline.surrogates.SURROGATES`` under the
manifest's ``model.type``; tests/test_surrogate_contract.py runs over every one of them.

Modules implementing the seam import numpy, scipy and the standard library at import time only
(the runtime loads them); fitting may import scikit-learn inside ``fit`` / ``regressor``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pipeline.artifact import Arrays, ArraySpec

if TYPE_CHECKING:
    from pipeline.surrogates.section import SurrogateSection



@dataclass
class TrainingSet:
    """The training rows grouped by environment (frame), scaled (``pipeline.surrogates.fit``).

    env (n_env, D): E_s of every training frame; env_offsets (n_env + 1,): the rows of frame g
    are env_offsets[g]:env_offsets[g + 1]; rows_x (M, P): X_s of every row; rows_t (M,): the
    target t of every row.
    """

    env: NDArray[np.float64]
    env_offsets: NDArray[np.int64]
    rows_x: NDArray[np.float64]
    rows_t: NDArray[np.float64]

    def features(self) -> NDArray[np.float64]:
        """(M, D + P) scaled features [E_s, X_s] of every row."""
        counts = np.diff(self.env_offsets)
        return np.hstack([np.repeat(self.env, counts, axis=0), self.rows_x])


@dataclass
class Prediction:
    """Predicted target t per query point (C,), and whether each value is exact (C,): a
    surrogate that searches part of its rows certifies the values it knows to be exact."""

    t: NDArray[np.float64]
    exact: NDArray[np.bool_]


def environment_d2(env: NDArray[np.float64], e_s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Squared distance (n_env,) of every training frame's scaled environment to E_s (D,)."""
    diff = env - e_s
    return np.einsum("ij,ij->i", diff, diff)


@runtime_checkable
class Query(Protocol):
    """The surrogate at one environment E_s: predictions at unit parameter points U (C, P),
    each point's value independent of the other points of U (the selector keeps the values of
    points it asks again: ``pipeline.runtime.Selector._refine``)."""

    rows_searched: int

    def predict(self, U: NDArray[np.float64]) -> Prediction:
        """t at every point of U, exact or not."""
        ...

    def certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """t where it is exact, inf elsewhere: (C,)."""
        ...

    def candidate_values(self, candidates: NDArray[np.float64]) -> NDArray[np.float64]:
        """``certified`` at the search's candidate set (which it may have prepared for)."""
        ...


class Search(Protocol):
    """A surrogate prepared for one candidate set (built once per selector)."""

    def at(self, e_s: NDArray[np.float64], env_d2: NDArray[np.float64]) -> Query:
        """The query at E_s (D,); env_d2 (n_env,) = ``environment_d2(env, e_s)``."""
        ...


class Regressor(Protocol):
    """An estimator on flat feature rows (the cross-validation's view of a surrogate)."""

    def fit(self, features: NDArray[np.float64], t: NDArray[np.float64]) -> Regressor:
        """Fit on (M, D + P) features and (M,) targets; returns itself."""
        ...

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, D + P) -> (n,) targets."""
        ...


@runtime_checkable
class Surrogate(Protocol):
    """A fitted surrogate S(E_s, X_s) ~ t (module docstring).

    ``type`` is the manifest's ``model.type``; ``files`` the artifact arrays it adds to the
    common ones (env.npy, env_frames.npy, candidates.npy, pca_*.npy), with their specs;
    ``risk_aware``: its search honours the selector's ``risk`` option (mean + risk * std of the
    neighbours' targets; ``pipeline.surrogates.check_risk``); ``manifest_schema``: the JSON
    Schema of what ``to_json`` writes besides ``type`` and ``target`` (the artifact's schema
    takes it from the registry: ``pipeline.surrogates.writer.artifact_schema``).
    """

    type: ClassVar[str]
    files: ClassVar[dict[str, ArraySpec]]
    risk_aware: ClassVar[bool]
    manifest_schema: ClassVar[dict[str, Any]]

    @classmethod
    def fit(cls, training: TrainingSet, section: SurrogateSection) -> Surrogate:
        """The surrogate of ``training`` with the settings of ``section``."""
        ...

    @classmethod
    def regressor(cls, section: SurrogateSection, n_params: int) -> Regressor:
        """A fresh estimator of this kind (leave-one-sequence-out cross-validation) on flat
        rows [E_s, X_s] whose last ``n_params`` columns are X_s."""
        ...

    def predict(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, D + P) scaled features [E_s, X_s] -> (n,) targets."""
        ...

    def arrays(self) -> Arrays:
        """Its artifact files: name (one of ``files``) -> array."""
        ...

    def to_json(self) -> dict[str, Any]:
        """The manifest's ``model`` block: ``type``, ``target`` and its settings."""
        ...

    @classmethod
    def from_artifact(cls, model: Mapping[str, Any], arrays: Arrays) -> Surrogate:
        """Rebuild from the manifest's ``model`` block and the artifact's arrays (its ``files``
        and the common ones, already checked against their specs and finite); ValueError naming
        the first inconsistency."""
        ...

    def search(self, candidates_u: NDArray[np.float64], x_scale: float,
               options: Mapping[str, Any]) -> Search:
        """Prepare the queries over ``candidates_u`` (C, P) in the cube; X_s = x_scale * u.
        ``options``: the selector's settings (``subset_rows``, ``grouped``, ``risk``); each
        surrogate uses those it knows."""
        ...
