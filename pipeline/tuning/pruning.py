"""Stop hopeless trials early: a percentile pruner over the running RTE (the idea of Optuna's
``MedianPruner`` / ``PercentilePruner``; docs/design.md, "Stages").

A study has *checkpoints*: ``checkpoints - 1`` evenly spaced frames of each of its sequences
(a joint study also checks at the end of every sequence but the last). A trial's value at a
checkpoint (sequence s, frame k) is the mean of the RTE of the sequences it finished before s
and the *running* RTE of s: the mean translational RTE [%] over the segments of length L that
end at or before frame k. Its *curve* is its values at every checkpoint.

Before a trial starts, the tuner sets a threshold at every checkpoint from the trials it has
told the search (the finished ok trials 0..t-lag, so that it is as deterministic as the
proposals): the ``percentile``-th percentile of their values there, once ``min_trials`` of
them have one, and only from a ``warmup`` fraction of a sequence's frames on. A trial whose
value is above the threshold at a checkpoint stops there: it is *pruned*. Its objective (what
the search is told, and the trials table holds) is its value at that checkpoint; the
trajectory it ran so far is written, so the per-frame rows it earned stay.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section

F64 = NDArray[np.float64]


class PruningSection(Section):
    """params.yaml ``trials.pruning``: the percentile pruner (``percentile: null`` = off, the
    default; ``fixed.pruning`` turns it on for the joint study)."""

    percentile: float | None = Field(None, gt=0, lt=100)
    checkpoints: int = Field(10, ge=2, le=1000)
    warmup: float = Field(0.2, ge=0, lt=1)
    min_trials: int = Field(5, ge=1)


@dataclass(frozen=True)
class Checkpoint:
    """Frame ``frame`` of the study's sequence number ``sequence`` (0-based)."""

    sequence: int
    frame: int


class Pruned(Exception):  # noqa: N818 - control flow inside a trial, never shown
    """Raised inside a trial at the checkpoint where it is pruned."""

    def __init__(self, index: int, value: float, threshold: float, trajectory: Any) -> None:
        super().__init__(f"value {value:.4g} above {threshold:.4g}")
        self.index = index
        self.value = value
        self.threshold = threshold
        self.trajectory = trajectory  # Trajectory of the frames run (0..frames_run-1)
        self.frames_run = len(trajectory)


def checkpoints(frame_counts: Sequence[int], settings: PruningSection) -> list[Checkpoint]:
    """The checkpoints of a study over sequences of ``frame_counts`` frames, in run order."""
    c = settings.checkpoints
    out = []
    for s, n in enumerate(frame_counts):
        frames = sorted({max(0, math.ceil(n * i / c) - 1) for i in range(1, c)})
        if s < len(frame_counts) - 1:
            frames.append(n - 1)  # a joint study: the end of every sequence but the last
        out += [Checkpoint(s, k) for k in frames if k < n - 1 or s < len(frame_counts) - 1]
    return out


def thresholds(points: Sequence[Checkpoint], frame_counts: Sequence[int],
               reference: Sequence[Sequence[float]], settings: PruningSection
               ) -> tuple[float | None, ...]:
    """The threshold at every checkpoint (None: no check there) from the ``reference`` curves
    (the told ok trials')."""
    if settings.percentile is None:
        return tuple(None for _ in points)
    out: list[float | None] = []
    for i, point in enumerate(points):
        warm = point.sequence > 0 or (point.frame + 1) >= settings.warmup * frame_counts[0]
        values = [float(curve[i]) for curve in reference
                  if len(curve) > i and math.isfinite(curve[i])]
        if warm and len(values) >= settings.min_trials:
            out.append(float(np.percentile(values, settings.percentile)))
        else:
            out.append(None)
    return tuple(out)


def running_rte(gt: F64, est: F64, frame: int, length_m: float) -> float:
    """Mean translational RTE [%] of the segments of ``length_m`` that end at or before
    ``frame`` (NaN when none does); ``gt``, ``est``: (N, 4, 4) T_world_lidar, N > frame."""
    from pipeline.metrics.rte import per_frame_rte

    t_err, _ = per_frame_rte(gt[:frame + 1], est[:frame + 1], length_m)
    valid = t_err[np.isfinite(t_err)]
    return float(valid.mean()) if len(valid) else math.nan


def value_at(point: Checkpoint, done_rte: Sequence[float], gt: F64, est: F64,
             length_m: float) -> float:
    """A trial's value at ``point``: the mean of the finished sequences' RTE (``done_rte``)
    and the running RTE of the current one."""
    current = running_rte(gt, est, point.frame, length_m)
    values = [*done_rte, current]
    return float(np.mean(values)) if all(map(math.isfinite, values)) else math.nan


def curve_of(points: Sequence[Checkpoint], gts: Sequence[F64], ests: Sequence[F64 | None],
             length_m: float) -> tuple[float, ...]:
    """Values at ``points`` of a trial whose trajectory of sequence s is ``ests[s]`` (possibly
    partial: frames 0..len-1; None when not run); stops at the first point not reached."""
    from pipeline.metrics.rte import mean_rte_pct

    full: dict[int, float] = {}
    out = []
    for point in points:
        est = ests[point.sequence]
        if est is None or len(est) <= point.frame:
            break
        done = []
        for s in range(point.sequence):
            if s not in full:
                other = ests[s]
                full[s] = (mean_rte_pct(gts[s], other, length_m)
                           if other is not None and len(other) == len(gts[s]) else math.nan)
            done.append(full[s])
        out.append(value_at(point, done, gts[point.sequence], est, length_m))
    return tuple(out)


def watcher(checks: Mapping[int, tuple[int, float]], points: Sequence[Checkpoint],
            done_rte: Sequence[float], gt: F64, scans: Sequence[Any], length_m: float
            ) -> Callable[[int, list[F64]], None]:
    """``run_streaming``'s ``after_frame`` for one sequence: at a checked frame (``checks``:
    frame -> (checkpoint index, threshold)) raise Pruned when the value is above the
    threshold (a NaN value never prunes)."""
    from pipeline.trajectory import Trajectory

    def after_frame(i: int, poses: list[F64]) -> None:
        hit = checks.get(i)
        if hit is None:
            return
        index, threshold = hit
        est = np.stack(poses)
        value = value_at(points[index], done_rte, gt, est, length_m)
        if value > threshold:
            run = scans[:i + 1]
            raise Pruned(index, value, threshold, Trajectory(
                np.array([s.frame for s in run], np.int32),
                np.array([s.stamp_ns for s in run], np.int64), est))

    return after_frame


def describe(settings: PruningSection) -> dict[str, Any]:
    """The settings as they enter the study fingerprint."""
    return settings.model_dump()


def reference_curves(done: Mapping[int, Any], tid: int, lag: int) -> list[Sequence[float]]:
    """Curves of the ok trials among 0..tid-lag (the ones told to the search for ``tid``)."""
    return [done[t].curve for t in range(tid - lag + 1)
            if t in done and done[t].status == "ok" and done[t].curve]


class StudyPruner:
    """The pruner of one study: its checkpoints over the study's sequences (ground truths
    ``gts``), the curves of trials an earlier run finished, and each new trial's thresholds.
    It reads and writes nothing: the study hands it the ground truths and the stored
    trajectories."""

    def __init__(self, gts: Sequence[F64], settings: PruningSection, length_m: float) -> None:
        self.settings = settings
        self.length_m = length_m
        self.gts: list[F64] = []
        self.points: list[Checkpoint] = []
        if settings.percentile is not None:
            self.gts = list(gts)
            self.points = checkpoints([len(g) for g in self.gts], settings)

    @property
    def active(self) -> bool:
        """True when the study prunes (``percentile`` set)."""
        return bool(self.points)

    def restore(self, results: Mapping[int, Any],
                trajectories: Callable[[int], list[F64 | None]]) -> dict[int, Any]:
        """``results`` (TrialResult read from the table) with the curves of their stored
        trajectories (``trajectories(trial)``: per sequence T_world_lidar, partial for a pruned
        trial, None where not run)."""
        from dataclasses import replace

        if not self.points:
            return dict(results)
        out = {}
        for tid, r in results.items():
            if r.status in ("ok", "pruned"):
                r = replace(r, curve=curve_of(self.points, self.gts, trajectories(tid),
                                              self.length_m))
            out[tid] = r
        return out

    def job_fields(self, tid: int, done: Mapping[int, Any], lag: int) -> dict[str, Any]:
        """``checkpoints`` and ``thresholds`` of the TrialJob of trial ``tid``."""
        if not self.points:
            return {}
        limits = thresholds(self.points, [len(g) for g in self.gts],
                            reference_curves(done, tid, lag), self.settings)
        return {"checkpoints": tuple((p.sequence, p.frame) for p in self.points),
                "thresholds": limits}
