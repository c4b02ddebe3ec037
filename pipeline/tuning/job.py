"""One trial: run an adapter with fixed parameters over one or more sequences, score, write.

``TrialJob`` is the picklable description of a trial; ``TrialResult`` its outcome;
``evaluate_trial(job, adapter, scans)`` runs, checks, scores and writes it and raises on any
failure. Who runs it where (in the worker process, or in a trial server process killed at the
time limit) is ``pipeline.tuning.worker``'s business.

A failing odometry (an exception, a non-finite pose, lost frames, an implausible jump: a
frame-to-frame translation above ``jump_limit_m``, or a run past its time limit) makes a
*failed* result whose objective is ``penalty_pct`` (a fixed number, so that a resumed or repeated
run sees the same history) and whose ``error`` is one line of text. A trial the machinery lost
(its process killed from outside, e.g. by the OOM killer) is *lost*: never scored, retried.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import AdaptuneError, OdometryError
from pipeline.odometry.base import Adapter
from pipeline.sequence import read_ground_truth
from pipeline.trajectory import Trajectory
from pipeline.tuning.layout import trajectory_path

if TYPE_CHECKING:
    from pipeline.sequence import Scan

log = logging.getLogger(__name__)

MAX_ERROR_CHARS = 400
TRIALS_PURPOSE = "to score trials against"
"""What a trial needs the ground truth for (``read_ground_truth``'s message)."""


@dataclass(frozen=True)
class TrialJob:
    """Everything a worker needs for one trial (plain data, picklable).

    adapter: a registry name (``ndt``) or ``module:factory`` (``(**options) -> Adapter``).
    space: the parameter space the study searches (``trials.space`` applied), None = built-in.
    checkpoints, thresholds: where the trial's curve is measured, and where it is pruned
    (``pipeline.tuning.pruning``).
    algorithm: the name used in output paths (the adapter's ``name``).
    sequences: ((sequence name, MCAP path), ...); more than one for a joint trial.
    """

    adapter: str
    algorithm: str
    sequences: tuple[tuple[str, str], ...]
    trial: int
    seed: int
    params: dict[str, float]
    out_dir: str
    length_m: float
    penalty_pct: float
    jump_limit_m: float
    time_limit_s: float | None = None
    adapter_options: dict[str, Any] = field(default_factory=dict)
    space: list[dict[str, Any]] | None = None  # the study's space (ParameterSpace.to_json)
    checkpoints: tuple[tuple[int, int], ...] = ()  # (sequence index, frame): pruning.Checkpoint
    thresholds: tuple[float | None, ...] = ()  # per checkpoint: prune above it (None: no check)


@dataclass(frozen=True)
class TrialResult:
    """Outcome of one trial; objective: mean translational RTE [%] (over sequences) or penalty."""

    trial: int
    status: str  # 'ok' | 'failed' | 'pruned' | 'lost' (see the module docstring)
    error: str
    objective: float
    wall_time_s: float
    seed: int
    params: dict[str, float]
    rte_pct: dict[str, float] = field(default_factory=dict)
    odometry_s: float = 0.0
    curve: tuple[float, ...] = ()  # values at the study's checkpoints (pruning.curve_of)


def evaluate_trial(job: TrialJob, adapter: Adapter,
                   scans: Mapping[str, list[Scan]] | None = None,
                   truths: MutableMapping[str, NDArray[np.float64]] | None = None
                   ) -> dict[str, Any]:
    """Run, check, score and write every sequence of ``job`` with ``adapter``; raises on any
    failure.

    ``scans``: sequences already decoded, by MCAP path (the worker's scan cache); the others
    are read from their file. ``truths``: ground truth by path, read once and kept there.
    Returns {"status": "ok" | "pruned", "objective": mean RTE [%]
    over sequences (a pruned trial: its value where it stopped), "rte_pct": {sequence: RTE},
    "odometry_s", "curve": values at the checkpoints, "error": why it was pruned}.
    ``pipeline.odometry.run_sequence`` checks frames, stamps, finiteness; ``check_jump`` jumps.
    A trial is pruned only where its scans are cached and the adapter streams (``start``).
    """
    import time

    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.trajectory import write_trajectory
    from pipeline.tuning.pruning import Checkpoint, Pruned, curve_of

    points = [Checkpoint(s, k) for s, k in job.checkpoints]
    rte: dict[str, float] = {}
    gts: list[NDArray[np.float64]] = []
    ests: list[NDArray[np.float64] | None] = []
    odometry_s = 0.0
    truths = {} if truths is None else truths
    for index, (name, path) in enumerate(job.sequences):
        if path not in truths:
            truths[path] = read_ground_truth(path, TRIALS_PURPOSE)
        gt = truths[path]
        t0 = time.perf_counter()
        try:
            traj = _run(job, adapter, index, path, (scans or {}).get(path), gt, list(rte.values()))
        except Pruned as stop:
            odometry_s += time.perf_counter() - t0
            write_trajectory(trajectory_path(job.out_dir, job.algorithm, name, job.trial),
                             stop.trajectory, _metadata(job, name))
            return {"status": "pruned", "objective": stop.value, "rte_pct": rte,
                    "odometry_s": odometry_s,
                    "curve": curve_of(points, [*gts, gt], [*ests, stop.trajectory.T_world_lidar],
                                      job.length_m),
                    "error": f"pruned at {name} frame {stop.frames_run - 1}: running RTE "
                             f"{stop.value:.4g} % above {stop.threshold:.4g} %"}
        odometry_s += time.perf_counter() - t0
        check_jump(traj, job.jump_limit_m)
        rte[name] = mean_rte_pct(gt, traj.T_world_lidar, job.length_m)
        if not np.isfinite(rte[name]):
            raise OdometryError(f"{name}: no segment of {job.length_m} m to score")
        write_trajectory(trajectory_path(job.out_dir, job.algorithm, name, job.trial), traj,
                         _metadata(job, name))
        gts.append(gt)
        ests.append(traj.T_world_lidar)
    objective = float(np.mean(list(rte.values())))
    return {"status": "ok", "objective": objective, "rte_pct": rte, "odometry_s": odometry_s,
            "curve": curve_of(points, gts, ests, job.length_m), "error": ""}


def _metadata(job: TrialJob, sequence: str) -> dict[str, str]:
    return {"algorithm": job.algorithm, "sequence": sequence, "trial": str(job.trial),
            "params_json": json.dumps(job.params, sort_keys=True)}


def _run(job: TrialJob, adapter: Adapter, index: int, path: str, cached: list[Scan] | None,
         gt: NDArray[np.float64], done_rte: list[float]) -> Trajectory:
    """The checked trajectory of sequence ``index`` of ``job``; pruning.Pruned when the trial
    is pruned on it."""
    from pipeline.odometry import check_trajectory, make_schedule, run_sequence
    from pipeline.odometry.base import run_streaming
    from pipeline.tuning.pruning import Checkpoint, watcher

    if cached is None or getattr(adapter, "accepts_time_limit", False):
        return run_sequence(adapter, path, job.params, job.time_limit_s)
    schedule = make_schedule(adapter, job.params, len(cached), path)
    checks = {k: (i, thr) for i, ((s, k), thr) in enumerate(zip(job.checkpoints, job.thresholds,
                                                               strict=True))
              if s == index and thr is not None}
    start = getattr(adapter, "start", None)
    if checks and start is not None:
        watch = watcher(checks, [Checkpoint(s, k) for s, k in job.checkpoints], done_rte, gt,
                        cached, job.length_m)
        traj = run_streaming(start, cached, schedule, after_frame=watch)
    else:
        traj = adapter.run(cached, schedule)
    stamps_ns = np.array([sc.stamp_ns for sc in cached])
    check_trajectory(traj, stamps_ns, f"{adapter.name} on {path}")
    return traj


def check_jump(traj: Trajectory, jump_limit_m: float) -> None:
    """OdometryError when a frame-to-frame translation exceeds ``jump_limit_m`` [m]."""
    if len(traj) > 1:
        step_m = np.linalg.norm(np.diff(traj.T_world_lidar[:, :3, 3], axis=0), axis=1)
        k = int(np.argmax(step_m))
        if not step_m[k] <= jump_limit_m:
            raise OdometryError(f"implausible jump of {step_m[k]:.3g} m at frame {k + 1} "
                                f"(jump_limit_m={jump_limit_m})")


def one_line(exc: BaseException) -> str:
    """``exc`` as one line of at most MAX_ERROR_CHARS (adaptune's own errors without their
    type: their message says it)."""
    text = str(exc) if isinstance(exc, AdaptuneError) else f"{type(exc).__name__}: {exc}"
    text = " ".join(text.split())
    return text[:MAX_ERROR_CHARS]


def remove_trajectories(job: TrialJob) -> None:
    """Drop trajectory files of a failed trial (e.g. left by an earlier, killed run)."""
    for name, _ in job.sequences:
        trajectory_path(job.out_dir, job.algorithm, name, job.trial).unlink(missing_ok=True)
