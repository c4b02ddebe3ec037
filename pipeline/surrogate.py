"""PCA of the descriptors, scaling, the kNN surrogate S(E, x) ~ y, its cross-validation and the
artifact writer (DESIGN sections 1 and 4). The deployable reader is ``pipeline.runtime``.

Scalings (every choice the paper leaves open):

- Descriptor -> environment E (PCA, ``Pca``): h = sqrt(d) of the normalised histogram (the
  Hellinger transform: Euclidean distances of sqrt-histograms are Hellinger distances, and the
  few dominant bins no longer swamp the rare ones); centred by the training mean; divided by
  one global scale (the RMS of the centred training features, stored per bin as ``scale``, all
  bins equal) -- a per-bin standardisation was rejected because bins that are nearly always
  empty (e.g. oblique lines at 27-30 m) would be blown up to unit variance; then projected on
  the top ``dim`` right singular vectors (numpy SVD) of the training frames only.
- Surrogate features: E_s = w_e * E / e_scale with e_scale the RMS per dimension of E over the
  training frames (one number: the PCA geometry is kept, an average dimension has unit
  variance); X_s = w_x * sqrt(12) * u where u = ParameterSpace.to_unit(x) in [0, 1]^P (log
  parameters on a log scale; sqrt(12) gives a uniformly sampled parameter unit variance).
  Distance: Euclidean on [E_s, X_s].
- Target: t = log1p(y) (``target: log``, default) or t = y (``linear``). kNN averages t, so with
  ``log`` one diverged trial (y of tens of %) no longer dominates the mean of its neighbours.
  Predictions are reported back in y units (expm1).
- kNN: k nearest rows, uniform weights (scikit-learn KNeighborsRegressor for fitting and CV).
- Cross-validation: leave-one-sequence-out. MAE and RMSE in y units; and a regret: for every
  held-out frame, the trial the surrogate ranks best among that frame's trials against the best
  trial of that frame (mean of y_chosen - y_best, and of y_best, y_chosen).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.descriptor import DescriptorConfig, describe
from pipeline.errors import ArtifactError, ConfigError, InputError
from pipeline.runtime import MANIFEST_HASH_KEY, canonical_manifest_hash

log = logging.getLogger(__name__)

PCA_FILES = ("mean.npy", "components.npy", "scale.npy")
ARTIFACT_SCHEMA = "artifact.schema.json"


# ---------------------------------------------------------------------------------------------
# descriptors of sequences


def describe_sequence(
    path: str | Path, config: DescriptorConfig
) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.float32]]:
    """Descriptor of every frame of one sequence MCAP: frames (N,), stamps_ns (N,), (N, 90)."""
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        rows = [(scan.frame, scan.stamp_ns, describe(scan.points_lidar, config)) for scan in reader]
    if not rows:
        raise InputError(f"{path}: no frames")
    frames = np.array([r[0] for r in rows], np.int32)
    stamps = np.array([r[1] for r in rows], np.int64)
    return frames, stamps, np.stack([r[2] for r in rows]).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# PCA


@dataclass
class Pca:
    """E = ((sqrt(d) - mean) / scale) @ components.T; mean, scale (F,), components (D, F)."""

    mean: NDArray[np.float64]
    scale: NDArray[np.float64]
    components: NDArray[np.float64]
    explained_variance_ratio: NDArray[np.float64]
    n_train_frames: int = 0
    train_sequences: list[str] = field(default_factory=list)
    descriptor: dict[str, Any] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return int(self.components.shape[0])

    def transform(self, descriptors: NDArray[np.floating]) -> NDArray[np.float64]:
        """(N, F) descriptors -> (N, D) environment values."""
        h = np.sqrt(np.maximum(np.asarray(descriptors, np.float64), 0.0))
        return ((h - self.mean) / self.scale) @ self.components.T

    def to_json(self) -> dict[str, Any]:
        return {
            "transform": "hellinger_sqrt",
            "dim": self.dim,
            "features": int(self.mean.shape[0]),
            "n_train_frames": self.n_train_frames,
            "train_sequences": self.train_sequences,
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            "descriptor": dict(self.descriptor),
        }

    def save(self, folder: str | Path) -> None:
        """Write mean.npy, components.npy, scale.npy and pca.json (with sha256) into ``folder``,
        atomically (a temp folder renamed onto ``folder``)."""
        arrays = {"mean.npy": self.mean, "components.npy": self.components, "scale.npy": self.scale}
        with atomic_dir(folder) as tmp:
            meta = self.to_json()
            meta["files"] = {name: _save_npy(tmp / name, arr) for name, arr in arrays.items()}
            (tmp / "pca.json").write_text(json.dumps(meta, indent=2), encoding="utf-8")

    @classmethod
    def load(cls, folder: str | Path) -> Pca:
        """Read a folder written by ``save``; InputError when files are missing or altered."""
        folder = Path(folder)
        try:
            meta = json.loads((folder / "pca.json").read_text(encoding="utf-8"))
            arr = {}
            for name in PCA_FILES:
                data = (folder / name).read_bytes()
                if hashlib.sha256(data).hexdigest() != meta["files"][name]:
                    raise InputError(f"{folder / name}: sha256 does not match pca.json")
                arr[name] = np.load(folder / name, allow_pickle=False)
        except (FileNotFoundError, KeyError, ValueError) as exc:
            raise InputError(f"{folder}: not a PCA folder ({type(exc).__name__}: {exc})") from None
        return cls(
            arr["mean.npy"],
            arr["scale.npy"],
            arr["components.npy"],
            np.asarray(meta["explained_variance_ratio"]),
            int(meta["n_train_frames"]),
            list(meta["train_sequences"]),
            dict(meta.get("descriptor") or {}),
        )


def fit_pca(
    descriptors: NDArray[np.floating], dim: int, train_sequences: Sequence[str] = ()
) -> Pca:
    """PCA of (N, F) training descriptors to ``dim`` components (module docstring: scaling)."""
    d = np.asarray(descriptors, np.float64)
    if d.ndim != 2 or len(d) < 2:
        raise InputError(f"PCA needs at least 2 training frames, got {len(d)}")
    if dim > min(d.shape):
        raise ConfigError(
            f"descriptors.pca_dim must be <= min(frames, features) = {min(d.shape)}, got {dim}"
        )
    h = np.sqrt(np.maximum(d, 0.0))
    mean = h.mean(axis=0)
    centred = h - mean
    rms = float(np.sqrt(np.mean(centred**2))) or 1.0
    _, sv, vt = np.linalg.svd(centred / rms, full_matrices=False)
    var = sv**2
    comps = vt[:dim]
    # sign convention: the largest |loading| of every component is positive (deterministic)
    signs = np.sign(comps[np.arange(dim), np.argmax(np.abs(comps), axis=1)])
    comps = comps * np.where(signs == 0, 1.0, signs)[:, None]
    return Pca(
        mean, np.full(d.shape[1], rms), comps, var[:dim] / var.sum(), len(d), list(train_sequences)
    )


# ---------------------------------------------------------------------------------------------
# surrogate


@dataclass(frozen=True)
class SurrogateSettings:
    """Model settings (the ``surrogate`` params section)."""

    k: int = 5
    w_e: float = 1.0
    w_x: float = 1.0
    target: str = "log"
    n_sobol: int = 1024
    seed: int = 0
    cv_max_frames: int = 200
    novelty_quantile: float | None = 1.0


@dataclass
class TrainingRows:
    """The rows q_ij = [E_i, x_j] -> y_ij of one algorithm, as plain arrays.

    E: (M, D) environment values; U: (M, P) parameters mapped to [0, 1] (ParameterSpace.to_unit);
    y: (M,) RTE [%]; sequences: (M,) str; frames: (M,) int; trials: (M,) int.
    """

    E: NDArray[np.float64]
    U: NDArray[np.float64]
    y: NDArray[np.float64]
    sequences: NDArray[np.str_]
    frames: NDArray[np.int64]
    trials: NDArray[np.int64]

    def __post_init__(self) -> None:
        m = len(self.y)
        if m == 0:
            raise InputError("no surrogate rows (no ok trials with per-frame RTE and environment)")
        for name in ("E", "U", "sequences", "frames", "trials"):
            if len(getattr(self, name)) != m:
                raise InputError(
                    f"surrogate rows: {name} has {len(getattr(self, name))} rows, y has {m}"
                )
        bad = ~np.isfinite(self.y) | ~np.isfinite(self.E).all(1) | ~np.isfinite(self.U).all(1)
        if bad.any():
            raise InputError(f"surrogate rows: {int(bad.sum())} rows with NaN/inf values")


@dataclass
class FittedSurrogate:
    """The fitted model as the artifact stores it (rows grouped by environment = frame).

    env (n_env, D): scaled E_s of every training frame; env_offsets (n_env+1,): rows of env g are
    rows env_offsets[g]:env_offsets[g+1]; rows_x (M, P): scaled X_s; rows_t (M,): target t;
    candidates_u (C, P): candidate parameter vectors in [0, 1].
    """

    settings: SurrogateSettings
    e_scale: float
    x_scale: float
    env: NDArray[np.float64]
    env_offsets: NDArray[np.int64]
    env_sequences: list[str]
    env_frames: NDArray[np.int64]
    rows_x: NDArray[np.float64]
    rows_t: NDArray[np.float64]
    candidates_u: NDArray[np.float64]
    summary: dict[str, Any]
    cv: dict[str, Any]
    novelty_distance: float | None = None

    def joint_features(self) -> NDArray[np.float64]:
        """(M, D + P) scaled features [E_s, X_s] of every row."""
        counts = np.diff(self.env_offsets)
        return np.hstack([np.repeat(self.env, counts, axis=0), self.rows_x])


def to_target(y: NDArray[np.float64], target: str) -> NDArray[np.float64]:
    """y [%] -> the averaged target t."""
    return np.log1p(np.maximum(y, 0.0)) if target == "log" else np.asarray(y, np.float64)


def from_target(t: NDArray[np.float64], target: str) -> NDArray[np.float64]:
    """Inverse of ``to_target``."""
    return np.expm1(t) if target == "log" else t


def fit_surrogate(
    rows: TrainingRows, space_json: list[dict[str, Any]], settings: SurrogateSettings
) -> FittedSurrogate:
    """Scale the rows, group them by environment, build candidates, cross-validate."""
    if settings.target not in ("log", "linear"):
        raise ConfigError(f"surrogate.target must be 'log' or 'linear', got {settings.target!r}")
    seq_names, seq_code = np.unique(rows.sequences.astype(str), return_inverse=True)
    seq_code = seq_code.reshape(-1).astype(np.int64)
    span = int(rows.frames.max()) + 1
    uniq, env_index = np.unique(seq_code * span + rows.frames, return_inverse=True)
    env_index = env_index.reshape(-1)
    order = np.argsort(env_index, kind="stable")
    first = np.zeros(len(uniq), np.int64)
    first[env_index[order][::-1]] = order[::-1]  # first row of each environment
    E_env = rows.E[first]
    e_scale = float(np.sqrt(np.mean((E_env - E_env.mean(0)) ** 2))) or 1.0
    x_scale = settings.w_x * math.sqrt(12.0)
    env = settings.w_e * E_env / e_scale
    counts = np.bincount(env_index, minlength=len(uniq))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rows_x = rows.U[order] * x_scale
    rows_t = to_target(rows.y[order], settings.target)
    cands = candidate_set(rows.U, len(space_json), settings.n_sobol, settings.seed)
    summary = {
        "rows": len(rows.y),
        "environments": len(uniq),
        "sequences": sorted(set(rows.sequences.tolist())),
        "trials": len(np.unique(seq_code * (int(rows.trials.max()) + 1) + rows.trials)),
        "y_mean": float(rows.y.mean()),
        "y_median": float(np.median(rows.y)),
        "candidates": len(cands),
    }
    cv = cross_validate(rows, settings, e_scale, x_scale)
    env_sequences = [str(seq_names[u // span]) for u in uniq]
    novelty = novelty_distance(env, np.array(env_sequences), settings.novelty_quantile)
    summary["novelty_distance"] = novelty
    return FittedSurrogate(
        settings,
        e_scale,
        x_scale,
        env,
        offsets,
        env_sequences,
        (uniq % span).astype(np.int64),
        rows_x,
        rows_t,
        cands,
        summary,
        cv,
        novelty,
    )


def novelty_distance(env: NDArray[np.float64], sequences: NDArray[np.str_],
                     quantile: float | None) -> float | None:
    """The ``quantile`` of every training frame's distance to the nearest frame of another
    training sequence (env (n_env, D) scaled environments, sequences (n_env,)): a scan farther
    than this from every training frame is unlike the training data (pipeline.runtime, step 7).
    None when disabled or with a single training sequence."""
    from scipy.spatial import cKDTree

    names = np.unique(sequences)
    if quantile is None or len(names) < 2:
        return None
    nearest = np.empty(len(env))
    for name in names:
        mine = sequences == name
        nearest[mine] = cKDTree(env[~mine]).query(env[mine])[0]
    return float(np.quantile(nearest, quantile))


NOVELTY_FALLBACKS = ("defaults", "fixed", "auto")


@dataclass
class FallbackEvidence:
    """The joint study's best parameters against the adapter defaults, per training sequence.

    fixed: the best 'ok' trial of the joint SMBO (the ``fixed`` stage); per_sequence: sequence
    -> (mean RTE [%] of the fixed parameters there, objective of that sequence's study trial run
    with the defaults: its mean RTE [%], or the failure penalty)."""

    fixed_trial: int
    fixed: dict[str, float]
    per_sequence: dict[str, tuple[float, float]]


def choose_fallback(
    mode: str, evidence: FallbackEvidence | None
) -> tuple[dict[str, float] | None, dict[str, Any]]:
    """Parameters for scans unlike every training frame (pipeline.runtime, step 7): None means
    the adapter's defaults. Returns (parameters or None, the record for the manifest).

    ``defaults``: the defaults. ``fixed``: the joint study's best parameters. ``auto``: the
    fixed parameters when they beat the defaults on every training sequence, else the defaults.
    The defaults are the out-of-distribution prior (hand-tuned for no environment in particular);
    they are dropped only when every environment seen shows them worse. Chosen on training data
    and dev composites, not on the validation sequence (README, "novelty fallback").
    """
    if mode not in NOVELTY_FALLBACKS:
        raise ConfigError(f"novelty_fallback must be one of {NOVELTY_FALLBACKS}, got {mode!r}")
    if mode == "defaults":
        return None, {"mode": mode, "chosen": "defaults"}
    if evidence is None:
        if mode == "fixed":
            raise InputError("novelty_fallback 'fixed' needs the joint study (the fixed stage)")
        return None, {"mode": mode, "chosen": "defaults", "reason": "no joint study"}
    record: dict[str, Any] = {
        "mode": mode,
        "fixed_trial": evidence.fixed_trial,
        "per_sequence": {
            seq: {"fixed_rte_pct": f, "defaults_rte_pct": d}
            for seq, (f, d) in sorted(evidence.per_sequence.items())
        },
    }
    use_fixed = mode == "fixed" or (
        bool(evidence.per_sequence) and all(f < d for f, d in evidence.per_sequence.values())
    )
    record["chosen"] = "fixed" if use_fixed else "defaults"
    return (dict(evidence.fixed) if use_fixed else None), record


def read_fallback_evidence(
    db_path: str | Path, algorithm: str, defaults: Mapping[str, float]
) -> FallbackEvidence | None:
    """``FallbackEvidence`` of ``algorithm`` from the results database (None without a
    successful joint trial or without the trials tables). A sequence whose study has no trial
    with the defaults is left out."""
    import duckdb

    con = duckdb.connect(str(db_path), read_only=True)
    try:
        tables = {r[0] for r in con.execute("SELECT table_name FROM duckdb_tables()").fetchall()}
        if not {"trials", "rte_frames"} <= tables:
            return None
        best = con.execute(
            "SELECT trial, params_json FROM trials WHERE study = 'fixed' AND algorithm = ? "
            "AND status = 'ok' AND objective IS NOT NULL ORDER BY objective, trial LIMIT 1",
            [algorithm],
        ).fetchone()
        if best is None:
            return None
        fixed_rte = con.execute(
            "SELECT sequence, avg(t_err_pct) FROM rte_frames WHERE study = 'fixed' "
            "AND algorithm = ? AND trial = ? GROUP BY sequence",
            [algorithm, best[0]],
        ).fetchall()
        studies = con.execute(
            "SELECT sequence, params_json, objective FROM trials WHERE study = 'trials' "
            "AND algorithm = ? AND objective IS NOT NULL ORDER BY sequence, trial",
            [algorithm],
        ).fetchall()
    finally:
        con.close()
    with_defaults: dict[str, float] = {}
    for seq, params_json, objective in studies:
        x = json.loads(params_json)
        if seq not in with_defaults and all(
            math.isclose(float(x.get(n, math.nan)), float(v), rel_tol=1e-9)
            for n, v in defaults.items()
        ):
            with_defaults[seq] = float(objective)
    per_sequence = {
        str(seq): (float(rte), with_defaults[seq])
        for seq, rte in fixed_rte
        if seq in with_defaults
    }
    fixed = {str(k): float(v) for k, v in json.loads(best[1]).items()}
    return FallbackEvidence(int(best[0]), fixed, per_sequence)


def novelty_fallback(
    db_path: str | Path, algorithm: str, space_json: list[dict[str, Any]], mode: str
) -> tuple[dict[str, float] | None, dict[str, Any]]:
    """``choose_fallback`` on the evidence of the results database (``mode`` 'defaults' reads
    nothing)."""
    if mode == "defaults":
        return choose_fallback(mode, None)
    defaults = {str(s["name"]): float(s["default"]) for s in space_json}
    return choose_fallback(mode, read_fallback_evidence(db_path, algorithm, defaults))


def candidate_set(
    U: NDArray[np.float64], n_params: int, n_sobol: int, seed: int
) -> NDArray[np.float64]:
    """(C, P) candidates in [0, 1]: every distinct trial parameter vector plus a Sobol set."""
    from scipy.stats import qmc

    distinct = np.unique(np.round(U, 12), axis=0)
    parts = [distinct]
    if n_sobol > 0:
        m = max(1, math.ceil(math.log2(n_sobol)))
        parts.append(qmc.Sobol(n_params, scramble=True, seed=seed).random_base2(m)[:n_sobol])
    return np.clip(np.vstack(parts), 0.0, 1.0)


def cross_validate(
    rows: TrainingRows, settings: SurrogateSettings, e_scale: float, x_scale: float
) -> dict[str, Any]:
    """Leave-one-sequence-out CV (module docstring). Held-out frames are subsampled to at most
    ``cv_max_frames`` per sequence (all trials of a kept frame stay, for the regret)."""
    from sklearn.neighbors import KNeighborsRegressor

    feats = np.hstack([settings.w_e * rows.E / e_scale, rows.U * x_scale])
    t = to_target(rows.y, settings.target)
    seqs = sorted(set(rows.sequences.tolist()))
    if len(seqs) < 2:
        return {
            "method": "leave-one-sequence-out",
            "folds": 0,
            "note": "needs >= 2 sequences",
            "mae": None,
            "rmse": None,
            "regret_mean": None,
            "per_sequence": {},
        }
    rng = np.random.default_rng(settings.seed)
    errs, per_seq, regrets, chosen, best = [], {}, [], [], []
    for seq in seqs:
        test = rows.sequences == seq
        train = ~test
        if train.sum() < settings.k:
            continue
        frames = np.unique(rows.frames[test])
        if len(frames) > settings.cv_max_frames:
            frames = rng.choice(frames, settings.cv_max_frames, replace=False)
        test &= np.isin(rows.frames, frames)
        model = KNeighborsRegressor(n_neighbors=settings.k).fit(feats[train], t[train])
        pred_y = from_target(model.predict(feats[test]), settings.target)
        true_y = rows.y[test]
        err = pred_y - true_y
        errs.append(err)
        per_seq[seq] = {
            "rows": int(test.sum()),
            "mae": float(np.mean(np.abs(err))),
            "rmse": float(np.sqrt(np.mean(err**2))),
        }
        fr = rows.frames[test]
        for f in np.unique(fr):
            sel = fr == f
            yt, yp = true_y[sel], pred_y[sel]
            regrets.append(yt[np.argmin(yp)] - yt.min())
            chosen.append(yt[np.argmin(yp)])
            best.append(yt.min())
    if not errs:
        return {
            "method": "leave-one-sequence-out",
            "folds": 0,
            "mae": None,
            "rmse": None,
            "regret_mean": None,
            "per_sequence": {},
        }
    e = np.concatenate(errs)
    return {
        "method": "leave-one-sequence-out",
        "folds": len(per_seq),
        "mae": float(np.mean(np.abs(e))),
        "rmse": float(np.sqrt(np.mean(e**2))),
        "regret_mean": float(np.mean(regrets)),
        "y_chosen_mean": float(np.mean(chosen)),
        "y_oracle_mean": float(np.mean(best)),
        "per_sequence": per_seq,
    }


# ---------------------------------------------------------------------------------------------
# the artifact


@dataclass
class ArtifactInfo:
    """What the manifest says besides the arrays."""

    algorithm: str
    space: list[dict[str, Any]]
    descriptor: DescriptorConfig
    selection: Mapping[str, Any]
    inputs: Mapping[str, str] = field(default_factory=dict)


def write_artifact(
    out: str | Path,
    fitted: FittedSurrogate,
    pca: Pca,
    info: ArtifactInfo,
    repo: str | Path | None = None,
) -> dict[str, Any]:
    """Write ``out``/ (manifest.json + .npy arrays) atomically; returns the manifest.

    The manifest is validated against schemas/artifact.schema.json before the rename.
    """
    from schemas import SCHEMA_VERSION

    arrays = {
        "env.npy": fitted.env,
        "env_offsets.npy": fitted.env_offsets,
        "env_frames.npy": fitted.env_frames,
        "rows_x.npy": fitted.rows_x,
        "rows_t.npy": fitted.rows_t,
        "candidates.npy": fitted.candidates_u,
        "pca_mean.npy": pca.mean,
        "pca_components.npy": pca.components,
        "pca_scale.npy": pca.scale,
    }
    with atomic_dir(out) as tmp:
        files = {name: _save_npy(tmp / name, arr) for name, arr in arrays.items()}
        manifest = {
            "schema_version": SCHEMA_VERSION,
            "kind": "adaptune.surrogate",
            "algorithm": info.algorithm,
            "parameter_space": info.space,
            "descriptor": info.descriptor.to_json(),
            "pca": pca.to_json(),
            "model": {
                "type": "knn",
                "k": fitted.settings.k,
                "weights": "uniform",
                "metric": "euclidean",
                "target": fitted.settings.target,
            },
            "scaling": {
                "environment": {
                    "w_e": fitted.settings.w_e,
                    "e_scale": fitted.e_scale,
                    "formula": "E_s = w_e * E / e_scale",
                },
                "parameters": {
                    "w_x": fitted.settings.w_x,
                    "x_scale": fitted.x_scale,
                    "formula": "X_s = x_scale * to_unit(x), x_scale = w_x*sqrt(12)",
                },
                "target": fitted.settings.target,
            },
            "selection": {**info.selection, "novelty_distance": fitted.novelty_distance},
            "training": {**fitted.summary, "env_sequences": fitted.env_sequences},
            "cross_validation": fitted.cv,
            "files": files,
            "provenance": provenance(repo, info.inputs),
        }
        validate_manifest(manifest)
        manifest[MANIFEST_HASH_KEY] = canonical_manifest_hash(manifest)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2), encoding="utf-8")
    return manifest


def validate_manifest(manifest: dict[str, Any]) -> None:
    """ArtifactError unless ``manifest`` follows schemas/artifact.schema.json."""
    import jsonschema

    from schemas import read_text

    try:
        jsonschema.validate(manifest, json.loads(read_text(ARTIFACT_SCHEMA)))
    except jsonschema.ValidationError as exc:
        path = "/".join(str(p) for p in exc.absolute_path) or "(root)"
        raise ArtifactError(f"manifest.json: {path}: {exc.message}") from None


def provenance(repo: str | Path | None, inputs: Mapping[str, str]) -> dict[str, Any]:
    """git revision (``git rev-parse HEAD``, dirty flag) and DVC info (md5 of the inputs from
    dvc.lock where present)."""
    repo = Path(repo) if repo else Path.cwd()
    git_rev, dirty = None, None
    try:
        git_rev = (
            subprocess.run(
                ["git", "rev-parse", "HEAD"],
                cwd=repo,
                capture_output=True,
                text=True,
                check=True,
                timeout=10,
            ).stdout.strip()
            or None
        )
        dirty = bool(
            subprocess.run(
                ["git", "status", "--porcelain", "--untracked-files=no"],
                cwd=repo,
                capture_output=True,
                text=True,
                timeout=10,
            ).stdout.strip()
        )
    except (OSError, subprocess.SubprocessError):
        pass
    return {
        "git_revision": git_rev,
        "git_dirty": dirty,
        "dvc": _dvc_lock_info(repo, inputs),
        "inputs": dict(inputs),
    }


def _dvc_lock_info(repo: Path, inputs: Mapping[str, str]) -> dict[str, Any] | None:
    lock = repo / "dvc.lock"
    if not lock.is_file():
        return None
    import yaml

    try:
        data = yaml.safe_load(lock.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError:
        return None
    wanted = {str(Path(p)) for p in inputs.values()}
    md5 = {}
    for stage in (data.get("stages") or {}).values():
        for out in stage.get("outs", []) or []:
            if str(Path(out.get("path", ""))) in wanted:
                md5[out["path"]] = out.get("md5")
    return {"dvc_lock_md5": hashlib.md5(lock.read_bytes()).hexdigest(), "inputs_md5": md5}


# ---------------------------------------------------------------------------------------------
# files


def _save_npy(path: Path, arr: NDArray[Any]) -> str:
    """np.save without pickle; returns the sha256 of the written file."""
    np.save(path, np.ascontiguousarray(arr), allow_pickle=False)
    return hashlib.sha256(path.read_bytes()).hexdigest()


class atomic_dir:  # noqa: N801 - used like contextlib helpers
    """Build a folder in a temp dir beside ``final``; on success replace ``final`` by it."""

    def __init__(self, final: str | Path) -> None:
        self.final = Path(final)

    def __enter__(self) -> Path:
        self.final.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(
            tempfile.mkdtemp(prefix=f".{self.final.name}.", suffix=".tmp", dir=self.final.parent)
        )
        return self.tmp

    def __exit__(self, exc_type: object, *rest: object) -> None:
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return
        old = None
        if self.final.exists():
            old = self.final.with_name(f".{self.final.name}.old.{os.getpid()}")
            os.replace(self.final, old)
        os.replace(self.tmp, self.final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


# ---------------------------------------------------------------------------------------------
# the descriptors of a data set (the `descriptors` stage)


@dataclass
class DescriptorSet:
    """Descriptors of every frame of every sequence, and the PCA fitted on the training ones."""

    sequences: NDArray[np.str_]
    frames: NDArray[np.int32]
    stamps_ns: NDArray[np.int64]
    descriptors: NDArray[np.float32]
    pca: Pca

    @property
    def environment(self) -> NDArray[np.float32]:
        return self.pca.transform(self.descriptors).astype(np.float32)


def read_index(sequences_dir: str | Path) -> dict[str, list[str]]:
    """``index.json`` of a sequences folder: split -> sequence names (file stems)."""
    path = Path(sequences_dir) / "index.json"
    try:
        index = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such index (written by the simulate stage)") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if (
        not isinstance(index, dict)
        or not isinstance(index.get("train"), list)
        or not index["train"]
    ):
        raise InputError(f"{path}: needs a non-empty 'train' list of sequence names")
    for split, names in index.items():
        for name in names:
            if not (Path(sequences_dir) / f"{name}.mcap").is_file():
                raise InputError(f"{path}: {split} sequence {name!r} has no {name}.mcap")
    return {str(k): [str(n) for n in v] for k, v in index.items()}


def _describe_job(args: tuple[str, DescriptorConfig]) -> tuple[NDArray[Any], ...]:
    return describe_sequence(args[0], args[1])


def describe_dataset(
    sequences_dir: str | Path, config: DescriptorConfig, pca_dim: int, workers: int = 1
) -> DescriptorSet:
    """Descriptor of every frame of every sequence in index.json (a process pool over the
    sequences) and the PCA fitted on the 'train' frames only."""
    from concurrent.futures import ProcessPoolExecutor

    index = read_index(sequences_dir)
    names = list(dict.fromkeys(n for split in index.values() for n in split))
    jobs = [(str(Path(sequences_dir) / f"{n}.mcap"), config) for n in names]
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(min(workers, len(jobs))) as pool:
            results = list(pool.map(_describe_job, jobs))
    else:
        results = [_describe_job(j) for j in jobs]
    seqs = np.concatenate(
        [np.full(len(r[0]), n, dtype=object) for n, r in zip(names, results, strict=True)]
    )
    frames = np.concatenate([r[0] for r in results])
    stamps = np.concatenate([r[1] for r in results])
    desc = np.concatenate([r[2] for r in results])
    train = np.isin(seqs, index["train"])
    pca = fit_pca(desc[train], pca_dim, index["train"])
    pca.descriptor = config.to_json()
    return DescriptorSet(seqs.astype(str), frames, stamps, desc, pca)


def write_descriptor_set(
    ds: DescriptorSet, out: str | Path, environment: str | Path, pca_dir: str | Path
) -> None:
    """descriptors Parquet (schemas.arrow.DESCRIPTORS), environment Parquet (sequence, frame,
    e0..) and the PCA folder, each written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.io_utils import atomic_path
    from schemas.arrow import DESCRIPTORS

    if ds.descriptors.shape[1] != 90:
        raise ConfigError(
            f"the DESCRIPTORS table has 90 columns, the descriptor has "
            f"{ds.descriptors.shape[1]} (range_bins must be 10)"
        )
    base = [pa.array(ds.sequences, pa.string()), pa.array(ds.frames, pa.int32())]
    cols = [*base, pa.array(ds.stamps_ns, pa.int64())]
    cols += [pa.array(ds.descriptors[:, i], pa.float32()) for i in range(90)]
    table = pa.Table.from_arrays(cols, schema=DESCRIPTORS)
    env = ds.environment
    env_schema = pa.schema(
        [
            pa.field("sequence", pa.string(), nullable=False),
            pa.field("frame", pa.int32(), nullable=False),
        ]
        + [pa.field(f"e{i}", pa.float32(), nullable=False) for i in range(env.shape[1])],
        metadata={**(DESCRIPTORS.metadata or {}), b"adaptune.table": b"environment"},
    )
    env_table = pa.Table.from_arrays(
        base + [pa.array(env[:, i], pa.float32()) for i in range(env.shape[1])], schema=env_schema
    )
    with atomic_path(out) as tmp:
        pq.write_table(table, tmp)
    with atomic_path(environment) as tmp:
        pq.write_table(env_table, tmp)
    ds.pca.save(pca_dir)


# ---------------------------------------------------------------------------------------------
# rows from the results database (the `surrogate` stage)


def read_training_rows(
    db_path: str | Path, algorithm: str | None, space_of: Any
) -> tuple[str, list[dict[str, Any]], TrainingRows]:
    """Rows of the ``surrogate_rows`` view of ``db_path`` for ``algorithm`` (None: the only one
    in the view). ``space_of(name)`` -> ParameterSpace. Returns (algorithm, space json, rows)."""
    import duckdb

    db_path = Path(db_path)
    if not db_path.is_file():
        raise InputError(f"{db_path}: no such results database (built by the rte stage)")
    try:
        con = duckdb.connect(str(db_path), read_only=True)
    except duckdb.Error as exc:
        raise InputError(f"{db_path}: not a DuckDB database ({exc})") from None
    try:
        try:
            algos = [
                r[0]
                for r in con.execute(
                    "SELECT DISTINCT algorithm FROM surrogate_rows ORDER BY 1"
                ).fetchall()
            ]
        except duckdb.Error as exc:
            raise InputError(
                f"{db_path}: no surrogate_rows view ({str(exc).splitlines()[0]})"
            ) from None
        if algorithm is None:
            if len(algos) != 1:
                raise ConfigError(
                    f"{db_path}: surrogate_rows holds algorithms {algos}; "
                    "choose one with --algorithm"
                )
            algorithm = algos[0]
        if algorithm not in algos:
            raise InputError(
                f"{db_path}: no surrogate rows for algorithm {algorithm!r} "
                f"(have: {', '.join(algos) or 'none'})"
            )
        space = space_of(algorithm)
        cols = [r[0] for r in con.execute("DESCRIBE surrogate_rows").fetchall()]
        e_cols = sorted(
            (c for c in cols if c[0] == "e" and c[1:].isdigit()), key=lambda c: int(c[1:])
        )
        p_cols = [f"p_{n}" for n in space.names]
        missing = [c for c in p_cols if c not in cols]
        if missing:
            raise InputError(f"{db_path}: surrogate_rows has no column {missing[0]}")
        sql = (
            f"SELECT sequence, trial, frame, {', '.join(e_cols)}, {', '.join(p_cols)}, y "
            "FROM surrogate_rows WHERE algorithm = ? AND y IS NOT NULL "
            "ORDER BY sequence, frame, trial"
        )
        table = con.execute(sql, [algorithm]).fetchnumpy()
    finally:
        con.close()
    E = np.column_stack([np.asarray(table[c], np.float64) for c in e_cols])
    X = np.column_stack([np.asarray(table[c], np.float64) for c in p_cols])
    U = (
        np.stack([space.to_unit(dict(zip(space.names, x, strict=True))) for x in X])
        if len(X) < 50_000
        else _to_unit_fast(space, X)
    )
    rows = TrainingRows(
        E,
        U,
        np.asarray(table["y"], np.float64),
        np.asarray(table["sequence"]).astype(str),
        np.asarray(table["frame"], np.int64),
        np.asarray(table["trial"], np.int64),
    )
    return algorithm, space.to_json(), rows


def _to_unit_fast(space: Any, X: NDArray[np.float64]) -> NDArray[np.float64]:
    """Vectorised ParameterSpace.to_unit for (M, P)."""
    out = np.empty_like(X)
    for j, s in enumerate(space.specs):
        lo, hi = (math.log(s.low), math.log(s.high)) if s.log else (s.low, s.high)
        x = np.log(X[:, j]) if s.log else X[:, j]
        out[:, j] = (x - lo) / (hi - lo) if hi > lo else 0.0
    return out
