"""Surrogates S(E, x) ~ y: the seam (``base``), its implementations and their registry.

``SURROGATES`` maps the manifest's ``model.type`` (params ``surrogate.model``) to the class; a
new surrogate is one module implementing ``pipeline.surrogates.base.Surrogate`` plus one line
here. Fitting (``fit``), cross-validation, the novelty guard and the training rows live beside
them; this package's import stays light (numpy, scipy), since the runtime loads it.
"""

from __future__ import annotations

import math

from pipeline.surrogates.base import Surrogate
from pipeline.surrogates.forest import ForestSurrogate
from pipeline.surrogates.knn import KnnSurrogate

SURROGATES: dict[str, type[Surrogate]] = {
    "knn": KnnSurrogate,
    "forest": ForestSurrogate,
}
"""Every registered surrogate by its manifest ``model.type``; the first is the default."""


def surrogate_class(type_name: str) -> type[Surrogate]:
    """The class registered as ``type_name``; KeyError naming the known ones."""
    try:
        return SURROGATES[type_name]
    except KeyError:
        raise KeyError(f"unknown surrogate type {type_name!r} "
                       f"(known: {', '.join(SURROGATES)})") from None


def check_risk(type_name: str, risk: float) -> None:
    """ValueError unless the surrogate ``type_name`` can weigh the selection setting ``risk``
    (mean + risk * std of the k neighbours' targets): risk > 0 needs a ``risk_aware`` one."""
    if not math.isfinite(risk) or risk < 0:
        raise ValueError(f"risk must be a finite number >= 0, got {risk!r}")
    aware = [name for name, cls in SURROGATES.items() if cls.risk_aware]
    if risk > 0 and type_name not in aware:
        raise ValueError(f"risk > 0 needs model {' or '.join(aware)}, "
                         f"got (model={type_name}, risk={risk:g})")
