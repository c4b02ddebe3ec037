"""Where a joint study starts: the parameters that the per-sequence studies predict best for
all sequences together (``fixed.warm_start``; docs/design.md, "Stages").

The joint objective is the mean over sequences of each sequence's RTE. Every per-sequence
study measured its own sequence's RTE at its own parameter sets (a failed trial at the
penalty, a pruned one at its running RTE where it stopped, a trial stopped at a rung of
successive halving at the penalty: it tells no more than TPE was told). Each sequence's RTE
is predicted at every parameter set any study measured, as the median objective of its own
study's ``K`` nearest trials in the unit cube; the ``n`` sets with the lowest predicted mean
come first.

Each study's own best parameters are no such start: on the toy they are 3.2 to 20 % RTE jointly
(tuned to one world, they fail in the other), the predicted ones 0.8 % to 0.9 %, near the best
that 256 joint trials find.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.odometry.base import ParameterSpace, Params
from pipeline.tuning.table import JOINT, read_space, read_study, read_trials, trials_path

K = 3
"""Trials of a study whose median predicts its sequence's RTE at a parameter set."""


def warm_start_params(out_dir: str | Path, algorithm: str, space: ParameterSpace,
                      n: int, sequences: Collection[str] | None = None) -> list[Params]:
    """The ``n`` parameter sets measured by the per-sequence studies of ``algorithm`` in the
    trials folder ``out_dir`` (``sequences``: of those sequences only) with the lowest
    predicted joint objective, best first. InputError when there is no study, or one searched
    another parameter space than ``space``."""
    found = read_space(out_dir, algorithm)
    if found.to_json() != space.to_json():
        raise InputError(f"{out_dir}: its studies searched another parameter space than this "
                         "one; a warm start needs the same")
    folder = trials_path(out_dir, algorithm, JOINT).parent.parent
    studies, measured = [], []
    for table in sorted(folder.glob("sequence=*/trials.parquet")):
        name = table.parent.name.removeprefix("sequence=")
        if name == JOINT or (sequences is not None and name not in sequences):
            continue
        results = [r for r in read_trials(table, space) if r.status != "lost"]
        if results:
            loss = told_loss(read_study(table))
            studies.append((np.array([space.to_unit(r.params) for r in results]),
                            np.array([loss(r.status, r.objective) for r in results])))
            measured += [r.params for r in results]
    if not studies:
        raise InputError(f"{out_dir}: no finished trial of {algorithm!r} to start from")
    _, first = np.unique(np.concatenate([u for u, _ in studies]), axis=0, return_index=True)
    candidates = sorted(first)  # each measured parameter set once, in the order read
    units = np.concatenate([u for u, _ in studies])[candidates]
    joint = np.mean([predicted(u, y, units) for u, y in studies], axis=0)
    return [measured[candidates[i]] for i in np.argsort(joint, kind="stable")[:n]]

def told_loss(study: Mapping[str, Any] | None) -> Callable[[str, float], float]:
    """What a study's trial tells about its sequence: its objective, but the penalty for a
    trial stopped at a rung of successive halving (a prefix's RTE; as TPE is told,
    ``pipeline.tuning.pruning.StoppingRule.told_loss``)."""
    halving = bool(study and study.get("fidelity"))
    penalty = float(study["penalty_pct"]) if study and halving else math.nan

    def loss(status: str, objective: float) -> float:
        return penalty if halving and status == "pruned" else objective

    return loss


def predicted(unit: NDArray[np.float64], objective: NDArray[np.float64],
              at: NDArray[np.float64]) -> NDArray[np.float64]:
    """A study's objective at the points ``at`` (M, D) of the unit cube: the median of its
    ``K`` nearest trials (``unit`` (N, D), ``objective`` (N,)). Returns (M,)."""
    dist = np.linalg.norm(at[:, None, :] - unit[None, :, :], axis=2)
    nearest = np.argsort(dist, axis=1, kind="stable")[:, :K]
    return np.median(objective[nearest], axis=1)
