"""The selector's runtime settings: params.yaml ``select``, one definition for the params
section, the ``adaptive`` / ``generalize`` stages, ``adaptune select`` / ``live`` and the
``Selector`` (pipeline/runtime.py documents what each one does).

They are not part of the model artifact: changing one refits nothing (the ``surrogate`` stage
does not read this section), and a deployment carries the model folder and these settings.
Each field carries its bounds (``Bound``); the params section's pydantic model is built from
them (``pipeline.config.section_model``), and ``SelectionSettings`` checks them itself, so the
runtime needs no pydantic. Standard library only: the deployable runtime imports this module.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any


@dataclass(frozen=True)
class Bound:
    """The range of a numeric setting: ``low`` (exclusive when ``strict``), ``high``."""

    low: float | None = None
    high: float | None = None
    strict: bool = False

    def check(self, name: str, value: Any, integer: bool, optional: bool) -> None:
        """ValueError naming ``name``, the rule and ``value`` unless it is in range."""
        if value is None and optional:
            return
        kind = "an integer" if integer else "a finite number"
        ok_type = (isinstance(value, int) if integer else isinstance(value, int | float))
        if isinstance(value, bool) or not ok_type or (not integer and not math.isfinite(value)):
            raise ValueError(f"{name} must be {kind}{self.text()}, got {value!r}")
        too_low = self.low is not None and (value <= self.low if self.strict else value < self.low)
        too_high = self.high is not None and value > self.high
        if too_low or too_high:
            raise ValueError(f"{name} must be {kind}{self.text()}, got {value!r}")

    def text(self) -> str:
        """`` > 0``, `` in [1, 60]``, ... (empty when unbounded)."""
        if self.low is not None and self.high is not None:
            return f" in {'(' if self.strict else '['}{self.low:g}, {self.high:g}]"
        if self.low is not None:
            return f" {'>' if self.strict else '>='} {self.low:g}"
        return f" <= {self.high:g}" if self.high is not None else ""


MAX_WINDOW = 60
"""The most scans a selection may average over (``window``)."""
MAX_REFINE_ITERS = 64
"""The most pattern-search rounds around the best candidates (``refine_iters``)."""


@dataclass(frozen=True)
class SelectionSettings:
    """params.yaml ``select``: how the selector uses the model (pipeline/runtime.py, steps).

    period_s: a selection every period_s [s] from the newest scan, held in between;
    hysteresis: new parameters replace the current ones only when predicted better by more
    than this (target units); min_scan_points: a scan with fewer points keeps the last
    parameters; subset_rows: rows of the kd-tree search, used only when the training frames do
    not group by trial set; refine_iters: pattern-search rounds around the best candidates;
    window: the mean of S over the last W familiar scans (the paper: 1, the newest only);
    anchor_margin: keep the fallback parameters unless the best is predicted better by more
    than this (target units; None: no anchor); risk: minimise mean + risk * std of the k
    neighbours' targets (kNN only; 0: the plain mean); trust_radius: search only within this
    distance of the fallback parameters in every unit-cube coordinate (None: the whole range).
    """

    period_s: Annotated[float, Bound(0.0, strict=True)] = 1.0
    hysteresis: Annotated[float, Bound(0.0)] = 0.02
    min_scan_points: Annotated[int, Bound(0)] = 1000
    subset_rows: Annotated[int, Bound(1)] = 4096
    refine_iters: Annotated[int, Bound(0, MAX_REFINE_ITERS)] = 4
    window: Annotated[int, Bound(1, MAX_WINDOW)] = 5
    anchor_margin: Annotated[float | None, Bound(0.0)] = None
    risk: Annotated[float, Bound(0.0)] = 0.0
    trust_radius: Annotated[float | None, Bound(0.0, 1.0, strict=True)] = None

    def __post_init__(self) -> None:
        for name, (bound, integer, optional) in _rules().items():
            bound.check(f"select.{name}", getattr(self, name), integer, optional)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any] | None) -> SelectionSettings:
        """The settings of a params ``select`` mapping (missing keys: the defaults);
        ValueError naming an unknown key or a value out of range."""
        data = dict(data or {})
        unknown = sorted(set(data) - set(_rules()))
        if unknown:
            raise ValueError(f"select.{unknown[0]}: unknown setting (known: "
                             f"{', '.join(_rules())})")
        ints = {n for n, (_, integer, _) in _rules().items() if integer}
        values = {k: (int(v) if k in ints and isinstance(v, float) and v.is_integer() else v)
                  for k, v in data.items()}
        return cls(**values)

    def replace(self, **changes: Any) -> SelectionSettings:
        """A copy with ``changes`` (None values are left out: "not given"), checked."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@functools.cache
def _rules() -> dict[str, tuple[Bound, bool, bool]]:
    """field -> (its Bound, integer?, may be None?) from the annotations."""
    return field_rules(SelectionSettings)


def field_rules(cls: type) -> dict[str, tuple[Bound, bool, bool]]:
    """The ``Bound`` of every ``Annotated[..., Bound(...)]`` field of dataclass ``cls``, with
    whether the field is an integer and whether it may be None."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        bound = next((m for m in getattr(hint, "__metadata__", ()) if isinstance(m, Bound)),
                     Bound())
        base = typing.get_args(hint)[0] if hasattr(hint, "__metadata__") else hint
        args = set(typing.get_args(base)) or {base}
        out[f.name] = (bound, int in args, type(None) in args)
    return out
