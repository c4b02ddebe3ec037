"""params.yaml ``surrogate``: how the model is fitted (its type, k, training rows,
scalings, target, candidates, cross-validation, novelty guard).

``rows``: ``trials``, the per-sequence SMBO's rows (the paper's; view ``surrogate_rows``), or
``portfolio``, every member of the portfolio study at every training frame (view
``portfolio_rows``; ``pipeline.portfolio``): with ``n_sobol: 0`` the candidates are
then the members, and a ``w_x`` that puts the members farther apart than any two frames makes
each member's prediction the mean over the k nearest frames of that member's own runs. The
selector's runtime settings are params ``select`` (``pipeline.selection``): changing them
refits nothing.

``model`` names a surrogate of the registry ``pipeline.surrogates.SURROGATES``; the name is
checked where the model is fitted (``pipeline.surrogates.surrogate_class``), so that this
module, which every surrogate's ``fit`` takes, imports none of them.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from pipeline.config import Section
from pipeline.surrogates.novelty import NoveltyFallback


class ForestSection(Section):
    """params.yaml ``surrogate.forest``: the random forest (pipeline/surrogates/forest.py)."""

    trees: int = Field(32, ge=1)
    min_samples_leaf: int = Field(5, ge=1)
    max_samples: int | None = Field(20000, ge=1)


class SurrogateSection(Section):
    """params.yaml ``surrogate`` (module docstring; pipeline/surrogates/fit.py documents the
    scalings and the target, pipeline/surrogates/novelty.py the novelty guard)."""

    model: str = "knn"
    rows: Literal["trials", "portfolio"] = "trials"
    k: int = Field(20, ge=1)
    w_e: float = Field(1.0, gt=0)
    w_x: float = Field(1.0, gt=0)
    target: Literal["log", "linear"] = "log"
    n_sobol: int = Field(1024, ge=0)
    seed: int = 0
    cv_max_frames: int = Field(200, ge=1)
    novelty_quantile: float | None = Field(1.0, gt=0, le=1)
    novelty_fallback: NoveltyFallback = "auto"
    forest: ForestSection = ForestSection.model_validate({})
