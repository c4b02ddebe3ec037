"""Replicas: how far a world's RTE moves when the parameters move imperceptibly.

An odometry whose failures are abrupt (NDT losing its map in a cave, a keyframe taken a
frame earlier) is chaotic in its parameters: on the dev suite, NDT's RTE on one world changes
with a coefficient of variation of 0.05 to 1.06 (median 0.3) when its two parameters change
by at most 0.5 % (README, "Worlds never trained on: the noise floor"). One run per setting
then cannot say whether adaptive beat min(baseline, fixed) on a world or drew a luckier run.

Replica r of a setting (r = 1 .. R) runs it again with every parameter multiplied by a factor
1 + u, u ~ U(-scale, scale), drawn per (world seed, r, parameter) and the same for the three
settings; values are clipped to the parameter's range and integers rounded, so an integer
parameter keeps its value. The adaptive replica multiplies the whole schedule of a parameter
by that parameter's factor: the selections are the same, the odometry sees values 0.5 %
apart. Replica 0 is the nominal run itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.odometry.base import ParameterSpace, Params, Schedule


def factors(seed: int, replica: int, n_params: int, scale: float) -> NDArray[np.float64]:
    """The multiplicative factors (n_params,) of replica ``replica`` (>= 1) of a world."""
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


def replica_rte(adapter: object, path: Path, params_or_schedule: Params | Schedule,
                gt: NDArray[np.float64], length_m: float) -> float:
    """Mean per-start-frame RTE [%] of one replica run (an odometry failure counts as NaN:
    the replicas measure the spread of successful runs, failures are counted apart)."""
    from pipeline.errors import OdometryError
    from pipeline.evaluation.rte import per_frame_rte
    from pipeline.odometry import run_sequence

    try:
        traj = run_sequence(adapter, path, params_or_schedule)  # type: ignore[arg-type]
    except OdometryError:
        return float("nan")
    t_err, _ = per_frame_rte(gt, traj.T_world_lidar, length_m)
    t = t_err[np.isfinite(t_err)]
    return float(t.mean()) if len(t) else float("nan")
