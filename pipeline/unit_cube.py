"""Parameter vectors <-> the unit cube [0, 1]^P, the one implementation of that mapping.

Each parameter maps its range [low, high] linearly onto [0, 1], on a log scale for ``log``
parameters; back from the cube, values are clipped to the range and ``int`` parameters
rounded (half to even). The surrogate works in the cube (its distances, its candidate set),
the tuner and the adapters in parameter values (docs/design.md, "Surrogate").

numpy and the standard library only: the deployable runtime imports it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class UnitCube:
    """The mapping of P ordered parameters: low, high (P,) [their units], log, integer (P,)."""

    names: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    log: tuple[bool, ...]
    integer: tuple[bool, ...]

    @classmethod
    def of(cls, specs: Iterable[Mapping[str, Any] | Any]) -> UnitCube:
        """From ParamSpec objects or their JSON dicts (name, low, high, kind, log)."""
        rows = [s if isinstance(s, Mapping) else vars(s) for s in specs]
        return cls(
            tuple(str(r["name"]) for r in rows),
            tuple(float(r["low"]) for r in rows),
            tuple(float(r["high"]) for r in rows),
            tuple(bool(r["log"]) for r in rows),
            tuple(r["kind"] == "int" for r in rows),
        )

    @property
    def dim(self) -> int:
        return len(self.names)

    def _bounds(self, j: int) -> tuple[float, float]:
        """Range of parameter j on its mapped scale (log of the bounds for log parameters)."""
        lo, hi = self.low[j], self.high[j]
        return (math.log(lo), math.log(hi)) if self.log[j] else (lo, hi)

    def to_unit(self, X: NDArray[np.floating]) -> NDArray[np.float64]:
        """(C, P) parameter values -> (C, P) points of the cube (not clipped)."""
        X = np.atleast_2d(np.asarray(X, np.float64))
        out = np.empty_like(X)
        for j in range(self.dim):
            lo, hi = self._bounds(j)
            x = np.log(X[:, j]) if self.log[j] else X[:, j]
            out[:, j] = (x - lo) / (hi - lo) if hi > lo else 0.0
        return out

    def from_unit(self, U: NDArray[np.floating]) -> NDArray[np.float64]:
        """(C, P) points (clipped to the cube) -> (C, P) values in range, ints rounded."""
        U = np.clip(np.atleast_2d(np.asarray(U, np.float64)), 0.0, 1.0)
        out = np.empty_like(U)
        for j in range(self.dim):
            lo, hi = self.low[j], self.high[j]
            if self.log[j]:
                v = np.exp(math.log(lo) + U[:, j] * (math.log(hi) - math.log(lo)))
            else:
                v = lo + U[:, j] * (hi - lo)
            v = np.round(v) if self.integer[j] else v
            out[:, j] = np.clip(v, lo, hi)
        return out

    def snap(self, U: NDArray[np.floating]) -> NDArray[np.float64]:
        """Points moved onto realisable parameters (ints rounded): (C, P)."""
        return self.to_unit(self.from_unit(U))

    def values(self, params: Mapping[str, float]) -> NDArray[np.float64]:
        """{name: value} -> (P,) in this order."""
        return np.array([float(params[n]) for n in self.names])

    def params(self, x: NDArray[np.floating]) -> dict[str, float]:
        """(P,) values -> {name: value}."""
        return {n: float(v) for n, v in zip(self.names, x, strict=True)}
