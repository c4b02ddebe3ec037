"""Fitting the surrogate S(E, x) ~ y from the training rows (docs/design.md, "Surrogate").

Scalings (every choice the paper leaves open):

- Surrogate features: E_s = w_e * E / e_scale with e_scale the RMS per dimension of E over the
  training frames (one number: the PCA geometry is kept, an average dimension has unit
  variance); X_s = w_x * sqrt(12) * u where u = ``UnitCube.to_unit(x)`` in [0, 1]^P (log
  parameters on a log scale; sqrt(12) gives a uniformly sampled parameter unit variance).
  Distance: Euclidean on [E_s, X_s].
- Target: t = log1p(y) (``target: log``, default) or t = y (``linear``). kNN averages t, so with
  ``log`` one diverged trial (y of tens of %) no longer dominates the mean of its neighbours.
  Predictions are reported back in y units (expm1).
- The surrogate itself: ``settings.model`` of the registry ``pipeline.surrogates.SURROGATES``
  (kNN: k nearest rows, uniform weights, the default; a random forest), fitted on the scaled
  rows grouped by frame (``TrainingSet``).
- Candidates: every distinct trial parameter vector plus a scrambled Sobol set in the cube.
- Cross-validation: ``pipeline.surrogates.cross_validation``; the novelty distance and the
  fallback parameters: ``pipeline.surrogates.novelty``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.surrogates.base import Surrogate, TrainingSet
from pipeline.surrogates.fitted import FittedSurrogate
from pipeline.surrogates.rows import TrainingRows
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.target import to_target

if TYPE_CHECKING:
    from pipeline.descriptors.dataset import DescriptorsSection


def fit_surrogate(
    rows: TrainingRows, space_json: list[dict[str, Any]], settings: SurrogateSection
) -> FittedSurrogate:
    """Scale the rows, group them by environment, fit ``settings.model``, build candidates,
    cross-validate."""
    from pipeline.surrogates.cross_validation import cross_validate
    from pipeline.surrogates.novelty import novelty_distance

    kind = registered(settings.model)
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
    training = TrainingSet(env, offsets, rows_x, rows_t)
    surrogate = kind.fit(training, settings)
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
    return FittedSurrogate(settings, e_scale, x_scale, env, env_sequences,
                           (uniq % span).astype(np.int64), surrogate, cands, summary, cv, novelty)


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


@dataclass(frozen=True)
class ModelInputs:
    """Where the ``surrogate`` stage reads from: the results database, the PCA folder."""

    db: Path
    pca: Path


def build_model(
    inputs: ModelInputs,
    out: str | Path,
    section: SurrogateSection,
    descriptors: DescriptorsSection,
    space_of: Callable[[str], Any],
    algorithm: str | None = None,
    options_of: Callable[[str], Mapping[str, Any]] = lambda _: {},
) -> dict[str, Any]:
    """The ``surrogate`` stage: read the training rows of ``algorithm`` (None: the only one),
    fit, choose the novelty fallback, write the artifact ``out``; returns its manifest.

    ``space_of(algorithm)`` -> the adapter's ParameterSpace (configured as in the trials);
    ``options_of(algorithm)`` -> the adapter options the trials ran with (in the artifact).
    The descriptor settings the PCA was fitted with win (pca.json); ``descriptors`` only
    stands in for a PCA folder that does not record them.
    """
    from pipeline.descriptors import descriptor_from_json
    from pipeline.pca import Pca
    from pipeline.surrogates.novelty import novelty_fallback
    from pipeline.surrogates.rows import read_training_rows
    from pipeline.surrogates.writer import ArtifactInfo, write_artifact

    registered(section.model)  # a misspelt model fails before the rows are read
    pca = Pca.load(inputs.pca)
    algo, space, rows = read_training_rows(inputs.db, algorithm, space_of, section.rows)
    fitted = fit_surrogate(rows, space, section)
    fallback, record = novelty_fallback(inputs.db, algo, space, section.novelty_fallback)
    descriptor = (
        descriptor_from_json(pca.descriptor) if pca.descriptor else descriptors.descriptor()
    )
    info = ArtifactInfo(algo, space, descriptor, record, fallback,
                        {"db": str(inputs.db), "pca": str(inputs.pca)}, options_of(algo))
    return write_artifact(out, fitted, pca, info)


def registered(model: str) -> type[Surrogate]:
    """The surrogate class ``surrogate.model`` names; ConfigError naming the known ones."""
    from pipeline.surrogates import surrogate_class

    try:
        return surrogate_class(model)
    except KeyError as exc:
        raise ConfigError(f"surrogate.model: {exc.args[0]}") from None
