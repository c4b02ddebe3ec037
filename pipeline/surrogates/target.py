"""The surrogate's target t: what its neighbours average (docs/design.md, "Surrogate")."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def to_target(y: NDArray[np.float64], target: str) -> NDArray[np.float64]:
    """y [%] -> the averaged target t."""
    return np.log1p(np.maximum(y, 0.0)) if target == "log" else np.asarray(y, np.float64)


def from_target(t: NDArray[np.float64], target: str) -> NDArray[np.float64]:
    """Inverse of ``to_target``."""
    return np.expm1(t) if target == "log" else t

