"""The deployable side: load the model artifact and pick parameters from a scan.

Imports numpy, scipy, the standard library and ``pipeline.descriptor`` only (a test checks that
importing this module pulls in none of sklearn, duckdb, hyperopt, open3d, dvc, pyarrow, click),
so a robot can carry ``model/`` and this file alone (the descriptor uses numba when it is
installed, numpy otherwise).

Selection (x_t = argmin_x S(E_t, x), S = the kNN mean of k training targets):

1. E_t = PCA(descriptor(scan)), scaled as the manifest says.
2. Since E_t is fixed for a query, the joint distance of a row i to (E_t, x) is
   |x - x_i|^2 + dE_i^2 with dE_i = |E_t - E_i|: the joint kNN is a kNN in P + 1 dimensions
   over the points (x_i, dE_i), queried at (x, 0).
3. Exact kNN over every row, grouped (``TrialGroups``): every frame of a training sequence has
   one row per trial of that sequence, the same parameter vectors in the same order, so the
   frames fall into a few groups (one per sequence) that share a block X_g of trial vectors.
   The k nearest rows of (E_t, x) are among the pairs (one of the k nearest trials of x in X_g,
   one of the k nearest frames of E_t in group g): any other row is farther than k rows of the
   same frame (nearer trials) or of the same trial (nearer frames). The nearest trials of the
   candidate set are static (found once per Selector); per selection only the k nearest frames
   of each group are found and the pairs merged (a numba kernel, numpy without numba).
   An artifact whose frames do not form at most ``MAX_GROUPS`` groups uses ``Neighbourhood``:
   the frames nearest to E_t are taken until ``subset_rows`` rows are gathered, a cKDTree over
   those rows' (x_i, dE_i) answers the k nearest rows, and a candidate is *certified exact*
   when its k-th neighbour distance is <= the E-distance of the first frame left out (every
   left-out row is at least that far), so it equals the kNN over all rows;
   ``Prediction.exact`` says which, and the search uses certified values only (the tree is
   searched within that distance, ``Neighbourhood.certified``).
4. argmin over the (certified) candidates (the artifact's candidate set: every distinct trial
   parameter vector plus a Sobol set), then a pattern search (``refine_iters`` rounds, step
   halving, moves accepted only to certified points) around the best few.
5. Hysteresis: the current parameters stay unless the new ones are predicted better by more
   than ``hysteresis`` (in target units: log1p(RTE %) for the default log target, so 0.05 is
   about 5 % relative).
6. A scan with fewer than ``min_scan_points`` points keeps the last parameters (the defaults
   before the first selection).
7. Novelty guard (not in the paper): when E_t is farther from every training environment than
   ``novelty_distance`` (a quantile, by default the largest, of the training frames' distances
   to the nearest frame of another training sequence, computed when the model is fitted), the
   surrogate would be extrapolating; the selector then falls back to the manifest's
   ``novelty_fallback_params`` (the joint study's fixed parameters, when the surrogate stage
   found them better than the defaults on every training sequence:
   ``pipeline.surrogates.novelty.choose_fallback``), else the adapter's defaults, until the
   scans look familiar again. ``null`` as novelty_distance disables it.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pipeline.artifact import ARTIFACT_KIND, MANIFEST_HASH_KEY, canonical_manifest_hash
from pipeline.descriptor import DescriptorConfig, describe
from pipeline.errors import ArtifactError
from pipeline.unit_cube import UnitCube

SCHEMA_VERSION = "1.0"  # = schemas.SCHEMA_VERSION (not imported: schemas pulls in nothing heavy
# today, but the runtime must stay importable on its own)
REQUIRED_FILES = (
    "env.npy",
    "env_offsets.npy",
    "env_frames.npy",
    "rows_x.npy",
    "rows_t.npy",
    "candidates.npy",
    "pca_mean.npy",
    "pca_components.npy",
    "pca_scale.npy",
)
Params = dict[str, float]


@dataclass
class Model:
    """A loaded, verified artifact (see ``pipeline.artifact.write_artifact`` for the arrays)."""

    path: Path
    manifest: dict[str, Any]
    descriptor: DescriptorConfig
    pca_mean: NDArray[np.float64]
    pca_scale: NDArray[np.float64]
    pca_components: NDArray[np.float64]
    env: NDArray[np.float64]
    env_offsets: NDArray[np.int64]
    rows_x: NDArray[np.float64]
    rows_t: NDArray[np.float64]
    candidates_u: NDArray[np.float64]
    space: list[dict[str, Any]] = field(default_factory=list)

    @property
    def algorithm(self) -> str:
        return str(self.manifest["algorithm"])

    @property
    def names(self) -> list[str]:
        return [str(s["name"]) for s in self.space]

    @property
    def k(self) -> int:
        return int(self.manifest["model"]["k"])

    @property
    def target(self) -> str:
        return str(self.manifest["model"]["target"])

    @property
    def selection(self) -> dict[str, Any]:
        return dict(self.manifest["selection"])

    @property
    def e_factor(self) -> float:
        env = self.manifest["scaling"]["environment"]
        return float(env["w_e"]) / float(env["e_scale"])

    @property
    def x_scale(self) -> float:
        return float(self.manifest["scaling"]["parameters"]["x_scale"])

    def defaults(self) -> Params:
        return {str(s["name"]): float(s["default"]) for s in self.space}

    def fallback(self) -> Params:
        """The parameters for unfamiliar scans (step 7): the manifest's
        ``novelty_fallback_params``, else the adapter's defaults."""
        chosen = self.manifest["selection"].get("novelty_fallback_params")
        return {n: float(chosen[n]) for n in self.names} if chosen else self.defaults()

    def environment(self, points_lidar: NDArray[np.floating]) -> NDArray[np.float64]:
        """Scaled environment E_s (D,) of one scan ((N, 3|4) points, sensor frame [m])."""
        d = describe(points_lidar, self.descriptor).astype(np.float64)
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
        return self.to_unit(self.from_unit(U))

    def params_of(self, u: NDArray[np.float64]) -> Params:
        """One unit point (P,) -> {name: value}."""
        return {n: float(v) for n, v in zip(self.names, self.from_unit(u)[0], strict=True)}


def load_model(path: str | Path, expected_algorithm: str | None = None) -> Model:
    """Load and verify ``path``/manifest.json and every file it lists (sha256, schema version,
    algorithm, shapes). ArtifactError with one line otherwise. Never unpickles anything."""
    path = Path(path)
    manifest = _read_manifest(path)
    major = str(manifest.get("schema_version", "")).split(".")[0]
    if major != SCHEMA_VERSION.split(".")[0]:
        raise ArtifactError(
            f"{path}: artifact schema version {manifest.get('schema_version')!r}, "
            f"this adaptune reads {SCHEMA_VERSION}"
        )
    algorithm = manifest.get("algorithm")
    if expected_algorithm is not None and algorithm != expected_algorithm:
        raise ArtifactError(
            f"{path}: artifact is for algorithm {algorithm!r}, expected {expected_algorithm!r}"
        )
    arrays = _read_arrays(path, manifest)
    try:
        model = Model(
            path,
            manifest,
            DescriptorConfig.from_json(manifest["descriptor"]),
            arrays["pca_mean.npy"],
            arrays["pca_scale.npy"],
            arrays["pca_components.npy"],
            arrays["env.npy"],
            arrays["env_offsets.npy"].astype(np.int64),
            arrays["rows_x.npy"],
            arrays["rows_t.npy"],
            arrays["candidates.npy"],
            list(manifest["parameter_space"]),
        )
        _check_shapes(model)
    except (KeyError, TypeError, ValueError) as exc:
        raise ArtifactError(
            f"{path}: inconsistent artifact ({type(exc).__name__}: {exc})"
        ) from None
    except Exception as exc:  # ConfigError from DescriptorConfig
        if exc.__class__.__name__ == "ConfigError":
            raise ArtifactError(f"{path}: {exc}") from None
        raise
    return model


def _read_manifest(path: Path) -> dict[str, Any]:
    mpath = path / "manifest.json"
    if not mpath.is_file():
        raise ArtifactError(f"{path}: not a model artifact (no manifest.json)")
    try:
        manifest = json.loads(mpath.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArtifactError(f"{mpath}: damaged manifest ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("kind") != ARTIFACT_KIND:
        raise ArtifactError(f"{mpath}: not an adaptune surrogate manifest")
    if manifest.get(MANIFEST_HASH_KEY) != canonical_manifest_hash(manifest):
        raise ArtifactError(f"{mpath}: manifest checksum mismatch (the manifest was altered)")
    return manifest


def _read_arrays(path: Path, manifest: dict[str, Any]) -> dict[str, NDArray[Any]]:
    files = manifest.get("files")
    if not isinstance(files, dict):
        raise ArtifactError(f"{path}/manifest.json: no file list")
    missing = [f for f in REQUIRED_FILES if f not in files]
    if missing:
        raise ArtifactError(f"{path}/manifest.json: does not list {missing[0]}")
    arrays = {}
    for name, digest in files.items():
        fpath = path / name
        if Path(name).name != name:
            raise ArtifactError(f"{path}/manifest.json: file name {name!r} is not a plain name")
        try:
            data = fpath.read_bytes()
        except FileNotFoundError:
            raise ArtifactError(f"{fpath}: missing (listed in manifest.json)") from None
        if hashlib.sha256(data).hexdigest() != digest:
            raise ArtifactError(f"{fpath}: sha256 mismatch (file altered or damaged)")
        try:
            arrays[name] = np.load(fpath, allow_pickle=False)
        except ValueError as exc:
            raise ArtifactError(f"{fpath}: not a plain numpy array ({exc})") from None
    return arrays


def _check_shapes(m: Model) -> None:
    n_env, d = m.env.shape
    p = len(m.space)
    rows = len(m.rows_t)
    problems = []
    if m.pca_components.shape != (d, m.descriptor.size):
        problems.append(f"pca_components {m.pca_components.shape} != ({d}, {m.descriptor.size})")
    if m.pca_mean.shape != (m.descriptor.size,) or m.pca_scale.shape != (m.descriptor.size,):
        problems.append("pca_mean/pca_scale length != descriptor size")
    if (
        m.env_offsets.shape != (n_env + 1,)
        or m.env_offsets[0] != 0
        or m.env_offsets[-1] != rows
        or np.any(np.diff(m.env_offsets) < 0)
    ):
        problems.append("env_offsets do not partition the rows")
    if m.rows_x.shape != (rows, p) or m.candidates_u.ndim != 2 or m.candidates_u.shape[1] != p:
        problems.append(
            f"rows_x {m.rows_x.shape} / candidates {m.candidates_u.shape} vs {p} parameters"
        )
    if problems:
        raise ArtifactError(f"{m.path}: inconsistent artifact ({problems[0]})")


@dataclass
class Prediction:
    """Predicted target t (mean of k rows) per query point, and whether it is certified exact."""

    t: NDArray[np.float64]
    exact: NDArray[np.bool_]


def environment_d2(model: Model, e_s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Squared distance (n_env,) of every training frame's scaled environment to E_s (D,)."""
    diff = model.env - e_s
    return np.einsum("ij,ij->i", diff, diff)


class Neighbourhood:
    """The rows near one environment E_s, as a (P + 1)-D tree (module docstring, step 3)."""

    def __init__(self, model: Model, e_s: NDArray[np.float64], subset_rows: int) -> None:
        d2 = environment_d2(model, e_s)
        self.nearest = float(np.sqrt(d2.min()))  # E-distance to the closest training frame
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
        self.x_scale = model.x_scale

    def predict(self, U: NDArray[np.float64]) -> Prediction:
        """Prediction at unit points U (C, P)."""
        dist, idx = self._query(U, math.inf)
        return Prediction(self.t[idx].mean(axis=1), dist[:, -1] ** 2 <= self.boundary2)

    def certified(self, U: NDArray[np.float64]) -> NDArray[np.float64]:
        """``predict(U).t`` where it is certified exact, inf elsewhere: (C,).

        The tree is searched only within the certification distance (inf: no bound), which
        prunes more of it than ``predict``."""
        dist, idx = self._query(U, math.sqrt(self.boundary2) * (1.0 + 1e-9) + 1e-12)
        exact = dist[:, -1] ** 2 <= self.boundary2
        t = np.full(len(U), np.inf)
        t[exact] = self.t[idx[exact]].mean(axis=1)
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


MAX_GROUPS = 64  # beyond this many frame groups the Selector uses Neighbourhood (step 3)


class TrialGroups:
    """The rows as groups of frames sharing one block of trial vectors (module docstring,
    step 3), with the k nearest trials of every candidate. Built once per Selector."""

    def __init__(
        self, model: Model, blocks: list[list[int]], candidates_u: NDArray[np.float64]
    ) -> None:
        """``blocks``: the frames of each group (frames whose rows hold the same trial vectors
        in the same order); candidates_u (C, P): the selector's candidate set."""
        offsets = model.env_offsets
        self.model = model
        self.k = model.k
        self.trees = [cKDTree(model.rows_x[offsets[f[0]] : offsets[f[0] + 1]]) for f in blocks]
        self.frame_table = np.full((len(blocks), max(map(len, blocks))), -1, np.int64)  # (G, F)
        for g, frames in enumerate(blocks):
            self.frame_table[g, : len(frames)] = frames
        self.candidates = candidates_u
        self.candidate_trials = self.nearest_trials(candidates_u)

    @classmethod
    def build(cls, model: Model, candidates_u: NDArray[np.float64]) -> TrialGroups | None:
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
        return cls(model, list(blocks.values()), candidates_u)

    def nearest_trials(
        self, U: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Squared distances and block positions (n, G, k) of the k nearest trial vectors of
        each unit point U (n, P) in every group (ascending; inf and 0 past a group's size)."""
        n = len(U)
        d2 = np.full((n, len(self.trees), self.k), np.inf)
        pos = np.zeros((n, len(self.trees), self.k), np.int64)
        q = U * self.model.x_scale
        for g, tree in enumerate(self.trees):
            kk = min(self.k, tree.n)
            dist, idx = tree.query(q, k=kk)
            d2[:, g, :kk] = np.reshape(dist, (n, kk)) ** 2
            pos[:, g, :kk] = np.reshape(idx, (n, kk))
        return d2, pos

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
    """TrialGroups at one environment E_s: the exact kNN over every row (step 3)."""

    def __init__(self, groups: TrialGroups, e_s: NDArray[np.float64]) -> None:
        env_d2 = environment_d2(groups.model, e_s)
        self.nearest = float(np.sqrt(env_d2.min()))  # E-distance to the closest training frame
        self.groups = groups
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
            self.groups.k,
        )


F64: TypeAlias = NDArray[np.float64]
I64: TypeAlias = NDArray[np.int64]


def knn_mean_numpy(
    trial_d2: F64, trial_pos: I64, frame_d2: F64, frame_row0: I64, rows_t: F64, k: int
) -> F64:
    """``pipeline.runtime_kernel.knn_mean`` in numpy (same arguments, same values): (n,).

    Only the pairs (a, j) with (a + 1)(j + 1) <= k can be among a group's k nearest: a pair
    farther down both sorted lists is beaten by the (a + 1)(j + 1) pairs above and left of it.
    """
    a, j = np.array([(a, j) for a in range(k) for j in range(k) if (a + 1) * (j + 1) <= k]).T
    n = len(trial_d2)
    d2 = (trial_d2[:, :, a] + frame_d2[None, :, j]).reshape(n, -1)
    rows = (trial_pos[:, :, a] + frame_row0[None, :, j]).reshape(n, -1)
    pick = np.argpartition(d2, k - 1, axis=1)[:, :k]
    return rows_t[np.take_along_axis(rows, pick, 1)].mean(axis=1)


KnnMean = Callable[..., NDArray[np.float64]]


@functools.cache
def _knn_mean_kernel() -> KnnMean:
    """``pipeline.runtime_kernel.knn_mean`` (numba), or ``knn_mean_numpy`` without numba."""
    try:
        from pipeline.runtime_kernel import knn_mean
    except ImportError:  # pragma: no cover - numba is a dependency of the pipeline, not the robot
        return knn_mean_numpy
    kernel: KnnMean = knn_mean
    return kernel


class Selector:
    """Online parameter selection from scans (module docstring). Settings default to the
    manifest's ``selection`` block."""

    def __init__(
        self,
        model: Model,
        period_s: float | None = None,
        hysteresis: float | None = None,
        min_scan_points: int | None = None,
        subset_rows: int | None = None,
        refine_iters: int | None = None,
        n_starts: int = 3,
        grouped: bool = True,
    ) -> None:
        sel = model.selection
        self.model = model
        self.period_s = float(sel["period_s"] if period_s is None else period_s)
        self.hysteresis = float(sel["hysteresis"] if hysteresis is None else hysteresis)
        self.min_scan_points = int(
            sel["min_scan_points"] if min_scan_points is None else min_scan_points
        )
        self.subset_rows = int(sel["subset_rows"] if subset_rows is None else subset_rows)
        self.refine_iters = int(sel["refine_iters"] if refine_iters is None else refine_iters)
        novelty = sel.get("novelty_distance")
        self.novelty_distance = math.inf if novelty is None else float(novelty)
        self.n_starts = n_starts
        self.candidates = np.unique(model.snap(model.candidates_u), axis=0)
        self.groups = TrialGroups.build(model, self.candidates) if grouped else None
        self.current_u: NDArray[np.float64] | None = None
        self.last_stamp_ns: int | None = None
        self.last: dict[str, Any] = {}
        self.selections = 0

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
        nb = self.neighbourhood(e_s)
        if nb.nearest > self.novelty_distance:  # an unfamiliar scan: the fallback (step 7)
            fallback = self.model.fallback()
            self.current_u = self.model.to_unit(
                np.array([[fallback[n] for n in self.model.names]]))[0]
            self.last = {"kept": "novel", "nearest_environment": nb.nearest}
            return fallback
        u_best, t_best, exact_frac = self._search(nb)
        kept = False
        if self.current_u is not None and not np.array_equal(u_best, self.current_u):
            t_cur = float(nb.predict(self.current_u[None]).t[0])
            if not t_best < t_cur - self.hysteresis:
                u_best, t_best, kept = self.current_u, t_cur, True
        self.current_u = u_best
        self.last = {
            "kept": "hysteresis" if kept else "",
            "predicted_t": t_best,
            "exact_fraction": exact_frac,
            "rows_searched": nb.rows_searched,
            "nearest_environment": nb.nearest,
        }
        return self.model.params_of(u_best)

    def neighbourhood(self, e_s: NDArray[np.float64]) -> GroupedNeighbourhood | Neighbourhood:
        """The search structure at E_s: exact over every row when the frames group (step 3)."""
        if self.groups is not None:
            return GroupedNeighbourhood(self.groups, e_s)
        return Neighbourhood(self.model, e_s, self.subset_rows)

    def _search(
        self, nb: GroupedNeighbourhood | Neighbourhood
    ) -> tuple[NDArray[np.float64], float, float]:
        t = nb.candidate_values(self.candidates)
        exact_frac = float(np.isfinite(t).mean())
        if exact_frac == 0.0:  # nothing certified: fall back to the approximate values
            t = nb.predict(self.candidates).t
        n = min(self.n_starts, len(t))
        starts = np.argsort(t, kind="stable")[:n]
        best_u, best_t = self.candidates[starts].copy(), t[starts].copy()
        step = 0.5 / max(2.0, len(self.candidates) ** (1.0 / self.candidates.shape[1]))
        p = self.candidates.shape[1]
        eye = np.vstack([np.eye(p), -np.eye(p)])
        for _ in range(self.refine_iters):
            probes = self.model.snap((best_u[:, None, :] + step * eye[None]).reshape(-1, p))
            pt = nb.certified(probes).reshape(n, 2 * p)
            j = np.argmin(pt, axis=1)
            better = pt[np.arange(n), j] < best_t
            if better.any():
                best_u[better] = probes.reshape(n, 2 * p, p)[better, j[better]]
                best_t[better] = pt[better, j[better]]
            else:
                step /= 2.0
        i = int(np.argmin(best_t))
        return best_u[i], float(best_t[i]), exact_frac

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


PARAMS_TOPIC = "/adaptune/params"
POSE_TOPIC = "/odometry/pose"


def params_json_schema(model: Model) -> dict[str, Any]:
    """JSON Schema of the ``/adaptune/params`` messages (Foxglove plots every number)."""
    props: dict[str, Any] = {n: {"type": "number"} for n in model.names}
    props.update(
        {
            "frame": {"type": "integer"},
            "selected": {"type": "boolean"},
            "predicted_rte_pct": {"type": ["number", "null"]},
            "kept": {"type": "string"},
        }
    )
    return {
        "type": "object",
        "title": "adaptune.params",
        "properties": props,
        "required": [*model.names, "frame"],
    }


def run_live(
    model: Model, sequence: str | Path, out: str | Path, selector: Selector | None = None
) -> dict[str, int]:
    """Stream ``sequence`` through the model's odometry (``adapter.start`` / ``set_params``),
    selecting parameters online; write ``out`` (scans, ground truth, poses, parameters).

    This is the one place of the runtime that needs the full pipeline (odometry adapters, the
    MCAP writer): imported lazily, so ``import pipeline.runtime`` stays light.
    """
    from pipeline.odometry.registry import get_adapter
    from pipeline.sequence import SequenceReader, SequenceWriter

    selector = selector or Selector(model)
    adapter = get_adapter(model.algorithm)
    schema = params_json_schema(model)
    odom = None
    selections = changes = 0
    with SequenceReader(sequence) as reader:
        info = reader.info
        info.extra = {
            **info.extra,
            "adaptune.model": str(model.path),
            "adaptune.algorithm": model.algorithm,
        }
        with SequenceWriter(out, info) as writer:
            for scan in reader:
                selected = selector.due(scan.stamp_ns)
                before = selector.current
                params = selector.update(scan.points_lidar, scan.stamp_ns)
                selections += selected
                if odom is None:
                    odom = adapter.start(params)  # type: ignore[attr-defined]
                elif params != before:
                    odom.set_params(params)
                    changes += 1
                T = odom.step(scan.xyz, scan.stamp_ns)
                writer.add(scan.stamp_ns, scan.points_lidar, scan.T_world_lidar)
                writer.add_pose(POSE_TOPIC, scan.stamp_ns, T)
                t = selector.last.get("predicted_t") if selected else None
                pred = None if t is None else float(np.expm1(t) if model.target == "log" else t)
                writer.add_json(
                    PARAMS_TOPIC,
                    scan.stamp_ns,
                    {
                        **params,
                        "frame": scan.frame,
                        "selected": bool(selected),
                        "predicted_rte_pct": pred,
                        "kept": str(selector.last.get("kept", "")) if selected else "",
                    },
                    schema,
                )
    return {"frames": len(reader), "selections": selections, "changes": changes}
