"""ParameterSpace <-> hyperopt search space.

Each ``ParamSpec`` becomes one hyperopt label of the same name:
float -> ``hp.uniform(low, high)``; float, log -> ``hp.loguniform(ln low, ln high)``;
int -> ``hp.quniform(low, high, 1)``; int, log -> ``hp.qloguniform(ln low, ln high, 1)``.
hyperopt stores these values as they are (no index encoding), so a trial's ``misc.vals`` is
``{name: [value]}`` and going back is a lookup, a clip to [low, high] and rounding of ints.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from pipeline.odometry.base import ParameterSpace, Params


def to_hyperopt(space: ParameterSpace) -> dict[str, Any]:
    """hyperopt space: a dict name -> hp expression (one label per parameter)."""
    from hyperopt import hp

    out: dict[str, Any] = {}
    for s in space.specs:
        if s.kind == "int" and s.log:
            out[s.name] = hp.qloguniform(s.name, math.log(s.low), math.log(s.high), 1)
        elif s.kind == "int":
            out[s.name] = hp.quniform(s.name, s.low, s.high, 1)
        elif s.log:
            out[s.name] = hp.loguniform(s.name, math.log(s.low), math.log(s.high))
        else:
            out[s.name] = hp.uniform(s.name, s.low, s.high)
    return out


def from_hyperopt_vals(space: ParameterSpace, vals: Mapping[str, Any]) -> Params:
    """Params from ``misc.vals`` ({name: [value]} or {name: value}); clipped, ints rounded."""
    out: Params = {}
    for s in space.specs:
        v = vals[s.name]
        v = float(v[0] if isinstance(v, list | tuple) else v)
        v = min(max(v, s.low), s.high)
        out[s.name] = float(round(v)) if s.kind == "int" else v
    return out


def to_hyperopt_vals(space: ParameterSpace, params: Mapping[str, float]) -> dict[str, list[float]]:
    """``misc.vals`` of a trial with these (validated) params: {name: [value]}."""
    checked = space.validate(params)
    return {name: [checked[name]] for name in space.names}
