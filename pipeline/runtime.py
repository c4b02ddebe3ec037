"""The deployable side: load the model artifact and pick parameters from a scan.

Imports numpy, scipy, the standard library and light pipeline modules only (a test checks that
importing this module pulls in none of sklearn, duckdb, hyperopt, open3d, dvc, pyarrow, click,
pydantic), so a robot can carry ``model/`` and this code alone (numba, when installed, speeds
up the descriptor and the kNN search).

Selection (x_t = argmin_x S(E_t, x), S = the artifact's surrogate), every ``period_s``; the
settings named below are the runtime's own (params ``select``: ``pipeline.selection``), not the
artifact's, so changing one refits nothing:

1. E_t = PCA(descriptor(scan)), scaled as the manifest says (``Model.environment``).
2. A scan with fewer than ``min_scan_points`` points keeps the last parameters (the defaults
   before the first selection).
3. Novelty guard (not in the paper): when E_t is farther from every training environment than
   the manifest's ``novelty.distance`` (a quantile, by default the largest, of the training
   frames' distances to the nearest frame of another training sequence, computed when the
   model is fitted), the
   surrogate would be extrapolating; the selector then falls back to the manifest's
   ``novelty_fallback_params`` (the joint study's fixed parameters, when the surrogate stage
   found them better than the defaults on every training sequence:
   ``pipeline.surrogates.novelty.choose_fallback``), else the adapter's defaults, until the
   scans look familiar again. ``null`` as the distance disables it. With the fallback
   ``per_scan`` (``Model.per_scan_fallback``) the surrogate does not search, but weighs those
   two only: each unfamiliar scan gets the defaults or the fixed parameters, whichever has the
   lower S (mean over the last W unfamiliar scans, the hysteresis as in step 7, ties to the
   parameters in force, then the defaults).
4. The surrogate's query at E_t (``pipeline.surrogates.base.Search``): for the kNN the exact
   k nearest rows over every row, grouped by trial set, or a certified kd-tree search
   (``pipeline.surrogates.knn_search``); for the forest a walk of its trees. With ``window``
   W > 1 the selector minimises the mean of S over the environments of the last W familiar
   scans (the paper's "environment descriptor sequence"; a novel scan empties the window).
   Risk (``risk``, kNN only; 0: off): S is then mean + risk * std of the k neighbours' targets
   (population std; ``knn_search.canonical_value``, computed by both searches), so a parameter
   vector whose neighbours disagree pays for their spread; the window, the anchor and the
   hysteresis below all compare these risk-adjusted values.
5. argmin over the (certified) candidates (the artifact's candidate set: every distinct trial
   parameter vector plus a Sobol set), then a pattern search (``refine_iters`` rounds, step
   halving, moves accepted only to certified points that are better by more than TIE_TOL)
   around the best few. Trust region (``trust_radius``, null: off): only the candidates and
   pattern-search points within ``trust_radius`` of the fallback parameters in every
   coordinate of the unit cube (and the fallback itself), so that a surrogate whose
   neighbours are bimodal cannot send the odometry to a lucky corner far from the set it
   falls back on. Values within TIE_TOL are equal: the kNN surface is piecewise
   constant, so many candidates share their value exactly (their neighbours are the same,
   ``knn_search.canonical_value``); among them the one nearest the parameters in force wins,
   then the smallest parameters, whatever the candidates' order or the last bits of E_t.
6. Anchor (``anchor_margin``, null: off): the fallback parameters (step 3) are kept unless the
   best is predicted better than them by more than ``anchor_margin`` (target units).
7. Hysteresis: the current parameters stay unless the new ones are predicted better by more
   than ``hysteresis`` (in target units: log1p(RTE %) for the default log target, so 0.05 is
   about 5 % relative).
"""

from __future__ import annotations

import collections
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.artifact import (
    COMMON_FILES,
    check_algorithm_space,
    read_arrays,
    read_manifest,
    validate_arrays,
    validate_values,
)
from pipeline.descriptors import Descriptor, descriptor_from_json
from pipeline.errors import ArtifactError, ConfigError
from pipeline.selection import SelectionSettings
from pipeline.surrogates.base import Query, Surrogate, environment_d2
from pipeline.unit_cube import UnitCube

Params = dict[str, float]


@dataclass
class Model:
    """A loaded, verified artifact (``pipeline.artifact`` describes the folder).

    pca_mean, pca_scale (F,), pca_components (D, F): the PCA of the descriptor; env (n_env, D):
    E_s of every training frame; candidates_u (C, P): the candidate set in the unit cube;
    surrogate: the ``pipeline.surrogates`` implementation the manifest's ``model.type`` names.
    """

    path: Path
    manifest: dict[str, Any]
    descriptor: Descriptor
    pca_mean: NDArray[np.float64]
    pca_scale: NDArray[np.float64]
    pca_components: NDArray[np.float64]
    env: NDArray[np.float64]
    candidates_u: NDArray[np.float64]
    surrogate: Surrogate
    space: list[dict[str, Any]] = field(default_factory=list)

    @property
    def algorithm(self) -> str:
        return str(self.manifest["algorithm"])

    @property
    def names(self) -> list[str]:
        return [str(s["name"]) for s in self.space]

    @property
    def target(self) -> str:
        return str(self.manifest["model"]["target"])

    @property
    def novelty_distance(self) -> float | None:
        """The novelty guard's distance in E_s (None: off; step 3)."""
        d = self.manifest["novelty"].get("distance")
        return None if d is None else float(d)

    @property
    def novelty_fallback(self) -> dict[str, Any]:
        """How the fallback was chosen: {"mode": ..., "chosen": ...} (surrogate stage)."""
        return dict(self.manifest["novelty"]["fallback"])

    @property
    def e_factor(self) -> float:
        env = self.manifest["scaling"]["environment"]
        return float(env["w_e"]) / float(env["e_scale"])

    @property
    def x_scale(self) -> float:
        return float(self.manifest["scaling"]["parameters"]["x_scale"])

    def defaults(self) -> Params:
        return {str(s["name"]): float(s["default"]) for s in self.space}

    @property
    def per_scan_fallback(self) -> bool:
        """True when every unfamiliar scan chooses between the defaults and the fixed
        parameters (surrogate.novelty_fallback ``per_scan``), not one fallback for all."""
        return self.novelty_fallback.get("chosen") == "per_scan"

    def fallback(self) -> Params:
        """The parameters for unfamiliar scans (step 3): the manifest's
        ``novelty.fallback_params``, else the adapter's defaults."""
        chosen = self.manifest["novelty"].get("fallback_params")
        return {n: float(chosen[n]) for n in self.names} if chosen else self.defaults()

    def environment(self, points_lidar: NDArray[np.floating]) -> NDArray[np.float64]:
        """Scaled environment E_s (D,) of one scan ((N, 3|4) points, sensor frame [m])."""
        d = self.descriptor.describe(points_lidar).astype(np.float64)
        e = ((np.sqrt(np.maximum(d, 0.0)) - self.pca_mean) / self.pca_scale) @ self.pca_components.T
        return e * self.e_factor

    @functools.cached_property
    def cube(self) -> UnitCube:
        """The parameter space's mapping to the unit cube."""
        return UnitCube.of(self.space)

    def from_unit(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """(C, P) in [0, 1] -> (C, P) parameter values (clipped; ints rounded)."""
        return self.cube.from_unit(U)

    def to_unit(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """(C, P) parameter values -> (C, P) in [0, 1]."""
        return self.cube.to_unit(X)

    def snap(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit points moved onto realisable parameters (ints rounded): (C, P)."""
        return self.cube.snap(U)

    def params_of(self, u: NDArray[np.float64]) -> Params:
        """One unit point (P,) -> {name: value}."""
        return self.cube.params(self.from_unit(u)[0])


def load_model(path: str | Path, expected_algorithm: str | None = None,
               declared_space: Callable[[str], Sequence[tuple[str, str]] | None] | None = None
               ) -> Model:
    """Load and verify the artifact ``path``: regular files inside the folder only, every
    checksum, the schema version, the algorithm, then every value and shape
    (``pipeline.artifact``). ArtifactError with one line otherwise. Never unpickles anything.

    ``declared_space``: algorithm name -> the (name, kind) pairs its adapter tunes
    (``pipeline.odometry.registry.declared_space``, which the pipeline's commands pass; the
    deployed runtime carries no adapters): the manifest's parameter space must match them."""
    from pipeline.surrogates import surrogate_class

    path = Path(path)
    manifest = read_manifest(path)
    algorithm = manifest.get("algorithm")
    if expected_algorithm is not None and algorithm != expected_algorithm:
        raise ArtifactError(
            f"{path}: artifact is for algorithm {algorithm!r}, expected {expected_algorithm!r}"
        )
    model_json = manifest.get("model")
    if not isinstance(model_json, dict):
        raise ArtifactError(f"{path}: manifest.json: no model block")
    try:
        kind = surrogate_class(str(model_json.get("type")))
    except KeyError as exc:
        raise ArtifactError(f"{path}: model.type: {exc.args[0]}") from None
    arrays = read_arrays(path, manifest, {**COMMON_FILES, **kind.files})
    try:
        validate_values(manifest)
        if declared_space is not None:
            check_algorithm_space(manifest, declared_space(str(algorithm)))
        descriptor = descriptor_from_json(manifest["descriptor"])
        validate_arrays(arrays, len(manifest["parameter_space"]), descriptor.size)
        surrogate = kind.from_artifact(model_json, arrays)
    except (ValueError, TypeError, KeyError, ConfigError) as exc:
        text = str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc)
        raise ArtifactError(f"{path}: inconsistent artifact ({text})") from None
    return Model(path, manifest, descriptor, arrays["pca_mean.npy"], arrays["pca_scale.npy"],
                 arrays["pca_components.npy"], arrays["env.npy"], arrays["candidates.npy"],
                 surrogate, list(manifest["parameter_space"]))


def trust_box(anchor_u: NDArray[np.float64],
              radius: float | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(low, high) (P,) of the unit-cube box the selector searches (step 5): within ``radius``
    of the fallback parameters ``anchor_u`` in every coordinate, inside [0, 1]; the whole
    cube for None."""
    if radius is None:
        return np.zeros_like(anchor_u), np.ones_like(anchor_u)
    return np.clip(anchor_u - radius, 0.0, 1.0), np.clip(anchor_u + radius, 0.0, 1.0)


TIE_TOL = 1e-9
"""Predicted values (target units) closer than this are equal for the selector (step 5)."""


class Selector:
    """Online parameter selection from scans with ``model`` (module docstring) and the runtime
    ``settings`` (params ``select``: ``pipeline.selection.SelectionSettings``; the defaults
    when not given). ConfigError when ``settings.risk`` > 0 for a surrogate that cannot weigh
    it. ``n_starts``: the candidates the pattern search starts from; ``grouped`` False forces
    the certified kd-tree search (the reference of the grouped one)."""

    def __init__(self, model: Model, settings: SelectionSettings | None = None, *,
                 n_starts: int = 3, grouped: bool = True) -> None:
        from pipeline.surrogates import check_risk

        self.settings = settings = settings or SelectionSettings()
        self.model = model
        self.period_s = settings.period_s
        self.hysteresis = settings.hysteresis
        self.min_scan_points = settings.min_scan_points
        self.subset_rows = settings.subset_rows
        self.refine_iters = settings.refine_iters
        self.window = settings.window
        self.anchor_margin = settings.anchor_margin
        self.risk = settings.risk
        try:
            check_risk(model.surrogate.type, self.risk)
        except ValueError as exc:
            raise ConfigError(f"select.{exc}") from None
        novelty = model.novelty_distance
        self.novelty_distance = math.inf if novelty is None else novelty
        self.n_starts = n_starts
        self.anchor_u = self._unit(model.fallback())
        self.box = trust_box(self.anchor_u, settings.trust_radius)
        candidates = model.snap(model.candidates_u)
        if settings.trust_radius is not None:  # step 5: only the candidates inside the box
            inside = ((candidates >= self.box[0]) & (candidates <= self.box[1])).all(axis=1)
            candidates = np.vstack([candidates[inside], model.snap(self.anchor_u[None])])
        self.candidates = np.unique(candidates, axis=0)
        self.search = model.surrogate.search(
            self.candidates, model.x_scale,
            {"subset_rows": self.subset_rows, "grouped": grouped, "risk": self.risk})
        # per_scan fallback: the two sets an unfamiliar scan chooses between (step 3)
        self.fallback_u = (np.stack([self._unit(model.defaults()), self.anchor_u])
                           if model.per_scan_fallback else self.anchor_u[None])
        self.current_u: NDArray[np.float64] | None = None
        self.recent: collections.deque[tuple[Query, NDArray[np.float64]]] = collections.deque(
            maxlen=max(1, self.window))
        self.recent_novel: collections.deque[NDArray[np.float64]] = collections.deque(
            maxlen=max(1, self.window))  # S at fallback_u of the last unfamiliar scans
        self.last_stamp_ns: int | None = None
        self.last: dict[str, Any] = {}
        self.selections = 0
        self.reuse = True  # the pattern search keeps known probes' values (off: searched again)

    @property
    def current(self) -> Params:
        """The parameters in force (the defaults before the first selection)."""
        if self.current_u is None:
            return self.model.defaults()
        return self.model.params_of(self.current_u)

    def due(self, stamp_ns: int) -> bool:
        """True when a selection is due at ``stamp_ns`` (first scan, or period_s elapsed)."""
        return (
            self.last_stamp_ns is None or stamp_ns - self.last_stamp_ns >= self.period_s * 1e9 - 1e6
        )

    def update(self, points_lidar: NDArray[np.floating], stamp_ns: int) -> Params:
        """Streaming use: select when due, else keep the parameters in force."""
        return self.select(points_lidar, stamp_ns) if self.due(stamp_ns) else self.current

    def select(self, points_lidar: NDArray[np.floating], stamp_ns: int | None = None) -> Params:
        """argmin_x S(E_t, x) for this scan, with hysteresis; too few points keep the last."""
        if stamp_ns is not None:
            self.last_stamp_ns = int(stamp_ns)
        self.selections += 1
        pts = np.asarray(points_lidar)
        if pts.ndim != 2 or len(pts) < self.min_scan_points:
            self.last = {"kept": "too_few_points", "points": len(pts)}
            return self.current
        return self.select_environment(self.model.environment(pts))

    def select_environment(self, e_s: NDArray[np.float64]) -> Params:
        """The selection for a scaled environment E_s (D,)."""
        env_d2 = environment_d2(self.model.env, e_s)
        nearest = float(np.sqrt(env_d2.min()))  # E-distance to the closest training frame
        if nearest > self.novelty_distance:  # an unfamiliar scan: the fallback (step 3)
            self.recent.clear()  # the window restarts with the next familiar scan
            self.current_u = self._fallback_for(e_s, env_d2)
            self.last = {"kept": "novel", "nearest_environment": nearest}
            return self.current  # the fallback as held: params_of(fallback_u), not the
            # manifest's own floats (7.774158360578929 comes back as ...928), or every novel
            # selection would be followed by a last-bit parameter change on the next frame
        self.recent_novel.clear()
        nb = self.search.at(e_s, env_d2)
        self.recent.append((nb, nb.candidate_values(self.candidates)))
        u_best, t_best, exact_frac = self._search()
        kept = ""
        if self.anchor_margin is not None and not np.array_equal(u_best, self.anchor_u):
            t_anchor = float(self._predict(self.anchor_u[None])[0])
            if not t_best < t_anchor - self.anchor_margin:
                u_best, t_best, kept = self.anchor_u.copy(), t_anchor, "anchor"
        if self.current_u is not None and not np.array_equal(u_best, self.current_u):
            t_cur = float(self._predict(self.current_u[None])[0])
            if not t_best < t_cur - self.hysteresis:
                u_best, t_best, kept = self.current_u, t_cur, "hysteresis"
        self.current_u = u_best
        self.last = {
            "kept": kept,
            "predicted_t": t_best,
            "exact_fraction": exact_frac,
            "rows_searched": nb.rows_searched,
            "nearest_environment": nearest,
        }
        return self.model.params_of(u_best)

    def _unit(self, params: Params) -> NDArray[np.float64]:
        """{name: value} -> its unit point (P,)."""
        return self.model.to_unit(np.array([[params[n] for n in self.model.names]]))[0]

    def _fallback_for(self, e_s: NDArray[np.float64],
                      env_d2: NDArray[np.float64]) -> NDArray[np.float64]:
        """The fallback's unit point for an unfamiliar scan (step 3): the one fallback, or
        with ``per_scan`` the defaults or the fixed parameters by S at E_s, averaged over the
        window's unfamiliar scans, with the hysteresis of step 7."""
        if len(self.fallback_u) == 1:
            return self.fallback_u[0].copy()
        self.recent_novel.append(self.search.at(e_s, env_d2).predict(self.fallback_u).t)
        t = np.mean(self.recent_novel, axis=0)
        held = [i for i, u in enumerate(self.fallback_u)
                if self.current_u is not None and np.array_equal(u, self.current_u)]
        best = 1 if t[1] < t[0] - TIE_TOL else 0
        if held and best != held[0] and not t[best] < t[held[0]] - self.hysteresis:
            best = held[0]
        return self.fallback_u[best].copy()

    def neighbourhood(self, e_s: NDArray[np.float64]) -> Query:
        """The surrogate's query at E_s (D,) (step 4)."""
        return self.search.at(e_s, environment_d2(self.model.env, e_s))

    def _predict(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """S at unit points U (C, P) averaged over the window's environments (exact or not)."""
        return np.mean([nb.predict(U).t for nb, _ in self.recent], axis=0)

    def _certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """``_predict`` where every value is certified exact, inf elsewhere: (C,).

        The scans' values are summed in window order, then divided by W: what numpy's mean
        over them does for C >= 2 points, and for each point the same bits whatever other
        points are asked with it (numpy sums a single point's W values pairwise, another
        order from W = 9 on), so ``_refine`` may ask for some of its probes only."""
        values = [nb.certified(U) for nb, _ in self.recent]
        total = values[0].copy()
        for v in values[1:]:
            total += v
        return total / len(values)

    def _order(self, t: NDArray[np.float64], U: NDArray[np.float64],
               first: int | None = None) -> NDArray[np.intp]:
        """Indices of U (C, P) by value t (C,), values within TIE_TOL of each other in one
        rank, ties by distance to the parameters in force (the anchor before the first
        selection), then by the parameters themselves: a rule that does not depend on the
        order of the candidates or on rounding (step 5). ``first``: only the first that many
        (the same ones: those of the lowest ranks are sorted, the rest cannot precede them)."""
        ref = self.anchor_u if self.current_u is None else self.current_u
        finite = t[np.isfinite(t)]
        rank = np.floor((t - (finite.min() if len(finite) else 0.0)) / TIE_TOL)
        pick = np.arange(len(t))
        if first is not None and first < len(t):
            pick = np.flatnonzero(rank <= np.partition(rank, first - 1)[first - 1])
        V = U[pick]
        keys = [V[:, j] for j in reversed(range(V.shape[1]))]
        order = pick[np.lexsort((*keys, ((V - ref) ** 2).sum(axis=1), rank[pick]))]
        return order if first is None else order[:first]

    def _search(self) -> tuple[NDArray[np.float64], float, float]:
        """Step 5: the best candidates by the window's mean value, refined by the pattern
        search; the best point (P,), its value and the fraction of certified candidates."""
        t = np.mean([values for _, values in self.recent], axis=0)
        exact_frac = float(np.isfinite(t).mean())
        if exact_frac == 0.0:  # nothing certified: fall back to the approximate values
            t = self._predict(self.candidates)
        n = min(self.n_starts, len(t))
        starts = self._order(t, self.candidates, first=n)
        best_u, best_t = self._refine(self.candidates[starts].copy(), t[starts].copy())
        i = int(self._order(best_t, best_u)[0])
        return best_u[i], float(best_t[i]), exact_frac

    def _refine(self, best_u: NDArray[np.float64],
                best_t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The pattern search (step 5) from the n starts best_u (n, P) of values best_t (n,):
        ``refine_iters`` rounds probing +-step along every coordinate of each start; a start
        moves to its best probe when that is better by more than TIE_TOL, and the step halves
        after a round where none moved. The starts and their values after the last round.

        A start that did not move in a round where another one did has the same probes in the
        next round: their values are kept, not searched again (``reuse``; the same values: a
        point's value does not depend on the other points asked, ``Query``)."""
        n, p = best_u.shape
        step = 0.5 / max(2.0, len(self.candidates) ** (1.0 / p))
        eye = np.vstack([np.eye(p), -np.eye(p)])
        probes = np.empty((n, 2 * p, p))
        pt = np.empty((n, 2 * p))
        ask = np.ones(n, bool)  # the starts whose probes' values are not known
        for _ in range(self.refine_iters):
            around = (best_u[ask][:, None, :] + step * eye[None]).reshape(-1, p)
            probes[ask] = self.model.snap(np.clip(around, *self.box)).reshape(-1, 2 * p, p)
            pt[ask] = self._certified(probes[ask].reshape(-1, p)).reshape(-1, 2 * p)
            j = np.argmin(pt, axis=1)
            moved = pt[np.arange(n), j] < best_t - TIE_TOL  # a real improvement, not rounding
            if moved.any():
                best_u[moved] = probes[moved, j[moved]]
                best_t[moved] = pt[moved, j[moved]]
            else:
                step /= 2.0
            ask = moved if self.reuse and moved.any() else np.ones(n, bool)
        return best_u, best_t

    def schedule(self, reader: Any) -> Any:
        """The Schedule of a whole recorded sequence (a SequenceReader): a selection every
        period_s from the newest scan, held in between."""
        from pipeline.odometry.base import Schedule

        stamps = np.asarray(reader.stamps_ns, np.int64)
        values = np.empty((len(stamps), len(self.model.names)))
        for i, stamp in enumerate(stamps):
            params = (
                self.select(reader[i].points_lidar, int(stamp))
                if self.due(int(stamp))
                else self.current
            )
            values[i] = [params[n] for n in self.model.names]
        return Schedule(
            np.arange(len(stamps), dtype=np.int32),
            {n: values[:, j].copy() for j, n in enumerate(self.model.names)},
            stamps,
        )
