"""A fitted surrogate and what the artifact stores beside it (``fit_surrogate`` makes it, the
writer stores it: ``pipeline.surrogates.fit``, ``pipeline.surrogates.writer``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.surrogates.base import Surrogate
from pipeline.surrogates.section import SurrogateSection


@dataclass
class FittedSurrogate:
    """A fitted model and what the artifact stores beside it.

    env (n_env, D): E_s of every training frame (env_sequences, env_frames: which one);
    surrogate: the fitted ``Surrogate`` (``settings.model``); candidates_u (C, P): candidate
    parameter vectors in [0, 1]; summary, cv: the training summary and the cross-validation.
    """

    settings: SurrogateSection
    e_scale: float
    x_scale: float
    env: NDArray[np.float64]
    env_sequences: list[str]
    env_frames: NDArray[np.int64]
    surrogate: Surrogate
    candidates_u: NDArray[np.float64]
    summary: dict[str, Any]
    cv: dict[str, Any]
    novelty_distance: float | None = None
