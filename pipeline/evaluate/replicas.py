"""Replicas: how far a sequence's RTE moves when the parameters move imperceptibly.

An odometry whose failures are abrupt (NDT losing its map in a cave, a keyframe taken a
frame earlier) is chaotic in its parameters: on the generalization suite's dev worlds, NDT's
RTE on one world changes with a coefficient of variation of about 0.3 when its two parameters
change by at most 0.5 % (docs/results/noise-floor.md). One run per setting then cannot say
whether adaptive beat min(baseline, fixed) on a world or drew a luckier run.

With ``replicas`` R > 0 the ``evaluate`` code (the evaluate and generalize stages) runs every
setting on every sequence R times more. Replica r (1 .. R) multiplies every parameter by a
factor 1 + u, u ~ U(-scale, scale), drawn from (the sequence's seed, r) and the same for the
three settings; values are clipped to the parameter's range and integers rounded, so an
integer parameter keeps its value. The adaptive replica multiplies the whole schedule of a
parameter by that parameter's factor: the selections are the same, the odometry sees values
0.5 % apart. Replica 0 is the nominal run itself. A replica whose odometry fails has no score
(the replicas measure the spread of successful runs; failures are counted).
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from pipeline.odometry.base import ParameterSpace, Params, Schedule


def sequence_seed(name: str) -> int:
    """The seed of a sequence's replica factors: from its name alone."""
    return zlib.crc32(name.encode("utf-8"))


def factors(seed: int, replica: int, n_params: int, scale: float) -> NDArray[np.float64]:
    """The multiplicative factors (n_params,) of replica ``replica`` (>= 1) of a sequence."""
    rng = np.random.default_rng([seed, replica])
    return 1.0 + rng.uniform(-scale, scale, n_params)


def _clipped(space: ParameterSpace, name: str, values: NDArray[np.float64]) -> NDArray[np.float64]:
    spec = space[name]
    out = np.clip(values, spec.low, spec.high)
    return np.round(out) if spec.kind == "int" else out


def perturbed_params(params: Mapping[str, float], space: ParameterSpace,
                     f: NDArray[np.float64]) -> Params:
    """``params`` with parameter j multiplied by f[j] (space order), clipped to the space."""
    return {n: float(_clipped(space, n, np.array([params[n] * f[j]]))[0])
            for j, n in enumerate(space.names)}


def perturbed_schedule(schedule: Schedule, space: ParameterSpace,
                       f: NDArray[np.float64]) -> Schedule:
    """``schedule`` with every value of parameter j multiplied by f[j], clipped."""
    values = {n: _clipped(space, n, schedule.values[n] * f[j]) for j, n in enumerate(space.names)}
    return Schedule(schedule.frames.copy(), values, schedule.stamps_ns)


def perturbed(params_or_schedule: Mapping[str, float] | Schedule, space: ParameterSpace,
              f: NDArray[np.float64]) -> Params | Schedule:
    """A setting's parameters (a constant set or an adaptive schedule) times the factors f."""
    if isinstance(params_or_schedule, Schedule):
        return perturbed_schedule(params_or_schedule, space, f)
    return perturbed_params(params_or_schedule, space, f)
