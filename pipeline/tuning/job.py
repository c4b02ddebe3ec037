"""One trial: run an adapter with fixed parameters over one or more sequences, score, write.

``TrialJob`` is the picklable description of a trial; ``TrialResult`` its outcome;
``evaluate_trial(job, adapter, scans)`` runs, checks, scores and writes it and raises on any
failure. Who runs it where (in the worker process, or in a trial server process killed at the
time limit) is ``pipeline.tuning.worker``'s business.

A failing odometry (an exception, a non-finite pose, lost frames, an implausible jump: a
frame-to-frame translation above ``jump_limit_m``, no segment to score, or a run past its time
limit) makes a *failed* result whose objective is ``penalty_pct`` (a fixed number, so that a
resumed or repeated run sees the same history) and whose ``error`` is one line of text. A trial
the machinery lost (its process killed from outside, e.g. by the OOM killer) is *lost*: never
scored, retried.

That is the rule ``failures: trial`` (the default). Under ``failures: sequence`` (a joint
study's ``fixed.failures``: ``SequenceFailures``) a sequence whose odometry fails counts alone:
it runs no further, writes no trajectory and counts at ``penalty_pct`` in the mean over the
sequences; the trial is ok when at least one sequence finished (else failed, as under the other
rule), and its ``error`` names every failed sequence and why. A time limit (the trial's, or a
sequence's ``TrialTimeout``) and the machinery's failures still end the whole trial.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
from collections.abc import Callable, Collection, Iterable, Mapping, MutableMapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import AdaptuneError, InfrastructureError, OdometryError, TrialTimeout
from pipeline.odometry.base import Adapter
from pipeline.sequence import read_ground_truth
from pipeline.trajectory import Trajectory
from pipeline.tuning.layout import trajectory_path
from pipeline.tuning.rung_board import RungBoard

if TYPE_CHECKING:
    from pipeline.sequence import Scan
    from pipeline.tuning.section import FailureRule

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
    (``pipeline.tuning.pruning``); with ``rungs`` (successive halving) the thresholds are set
    at each rung from the earlier trials' posts there (``pipeline.tuning.rung_board``).
    algorithm: the name used in output paths (the adapter's ``name``).
    sequences: ((sequence name, MCAP path), ...); more than one for a joint trial.
    length_m: the RTE length L [m] (base.length_m); lengths_m: each sequence's L, in the order
    of ``sequences`` (its own where it has one: ``SequenceInfo.length_m``), () for
    ``length_m`` everywhere (``sequence_lengths_m``). jump_limit_m, jump_limits_m: likewise
    the jump limit [m] (trials.jump_limit_m; ``SequenceInfo.jump_limit_m``) a sequence's
    trajectory is checked at (``check_jump``).
    failures: what a sequence whose odometry fails does to the trial (``trial``: fails it;
    ``sequence``: counts at the penalty on its own; module docstring).
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
    checkpoints: tuple[tuple[int, ...], ...] = ()  # frames per sequence: pruning.Checkpoint
    thresholds: tuple[float | None, ...] = ()  # per checkpoint: prune above it (None: no check)
    scored_only: bool = False  # values average the sequences scored so far (pruning.value_at)
    rungs: RungBoard | None = None  # successive halving: thresholds from the board, at the rung
    eta: int = 0  # successive halving's eta (with ``rungs``)
    lengths_m: tuple[float, ...] = ()  # per sequence; (): length_m for every one
    jump_limits_m: tuple[float, ...] = ()  # per sequence; (): jump_limit_m for every one
    failures: FailureRule = "trial"  # trials.failures (fixed.failures for the joint study)

    @property
    def sequence_lengths_m(self) -> tuple[float, ...]:
        """The RTE length L [m] of every sequence, in the order of ``sequences``."""
        return self.lengths_m or (self.length_m,) * len(self.sequences)

    def length_of(self, sequence: str) -> float:
        """The RTE length L [m] of the sequence named ``sequence``."""
        return self.sequence_lengths_m[self._index(sequence)]

    def jump_limit_of(self, sequence: str) -> float:
        """The jump limit [m] of the sequence named ``sequence``."""
        limits = self.jump_limits_m or (self.jump_limit_m,) * len(self.sequences)
        return limits[self._index(sequence)]

    def _index(self, sequence: str) -> int:
        return [name for name, _ in self.sequences].index(sequence)

    @property
    def limit_s(self) -> float | None:
        """The whole trial's time limit [s]: ``time_limit_s`` per sequence (None: no limit)."""
        return None if self.time_limit_s is None else self.time_limit_s * len(self.sequences)


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
                   truths: MutableMapping[str, NDArray[np.float64]] | None = None,
                   on_wait: Callable[[float], None] | None = None) -> dict[str, Any]:
    """Run, check, score and write every sequence of ``job`` with ``adapter``; raises on any
    failure.

    ``scans``: sequences already decoded, by MCAP path (the worker's scan cache); the others
    are read from their file. ``truths``: ground truth by path, read once and kept there.
    Returns {"status": "ok" | "pruned", "objective": mean RTE [%]
    over sequences (a pruned trial: its value where it stopped), "rte_pct": {sequence: RTE},
    "odometry_s", "curve": values at the checkpoints, "error": why it was pruned}.
    ``pipeline.odometry.run_sequence`` checks frames, stamps, finiteness; ``check_jump`` jumps.
    A trial with thresholds runs its sequences a frame at a time when the adapter streams
    (``start``), from the cache or from the file, and passes the checkpoints in order
    (``pipeline.tuning.pruning``); else every sequence runs whole. ``on_wait(seconds)``: told
    how long the trial waited at a rung for earlier trials (``RungBoard.threshold``).
    """
    from pipeline.tuning.pruning import Checkpoint

    truths = {} if truths is None else truths
    for _, path in job.sequences:
        if path not in truths:
            truths[path] = read_ground_truth(path, TRIALS_PURPOSE)
    gts = [truths[path] for _, path in job.sequences]
    points = [Checkpoint(tuple(frames)) for frames in job.checkpoints]
    streams = (getattr(adapter, "start", None) is not None
               and not getattr(adapter, "accepts_time_limit", False))
    if streams and (job.rungs is not None or any(t is not None for t in job.thresholds)):
        return _run_stepped(job, adapter, scans or {}, gts, points, on_wait)
    return _run_whole(job, adapter, scans or {}, gts, points)


def _run_whole(job: TrialJob, adapter: Adapter, scans: Mapping[str, list[Scan]],
               gts: list[NDArray[np.float64]], points: list[Any]) -> dict[str, Any]:
    """Every sequence of ``job`` run whole, one after the other (no checkpoint checked)."""
    import time

    rte: dict[str, float] = {}
    ests: list[NDArray[np.float64] | None] = []
    failed = SequenceFailures(job)
    odometry_s = 0.0
    for s, ((name, path), gt) in enumerate(zip(job.sequences, gts, strict=True)):
        try:
            t0 = time.perf_counter()
            try:
                traj = _run_one(job, adapter, path, scans.get(path))
            finally:
                odometry_s += time.perf_counter() - t0
            rte[name] = _score(job, name, gt, traj)
        except Exception as exc:
            if not failed.absorb(s, exc):
                raise
            ests.append(None)
            continue
        ests.append(traj.T_world_lidar)
    return {"status": "ok", "objective": failed.objective(rte), "rte_pct": rte,
            "odometry_s": odometry_s, "error": failed.text(),
            "curve": _curve(job, points, gts, ests, failed, ok=True)}


def _run_one(job: TrialJob, adapter: Adapter, path: str, cached: list[Scan] | None
             ) -> Trajectory:
    """One sequence of ``job`` run whole and checked: over its decoded scans ``cached``, or
    from its MCAP (``run_sequence``, with the time limit) when they are not cached or the
    adapter takes the time limit itself."""
    from pipeline.odometry import check_trajectory, make_schedule, run_sequence

    if cached is None or getattr(adapter, "accepts_time_limit", False):
        return run_sequence(adapter, path, job.params, job.time_limit_s)
    traj = adapter.run(cached, make_schedule(adapter, job.params, len(cached), path))
    check_trajectory(traj, np.array([sc.stamp_ns for sc in cached]), f"{adapter.name} on {path}")
    return traj


@dataclass
class SequenceFailures:
    """The sequences of a trial that failed on their own (``failures: sequence``): ``why``,
    by index in ``job.sequences``, in one line each. Under ``failures: trial`` it stays empty:
    ``absorb`` refuses every failure, which the caller raises on (the trial fails)."""

    job: TrialJob
    why: dict[int, str] = field(default_factory=dict)

    def absorb(self, index: int, exc: Exception) -> bool:
        """Under ``failures: sequence``, record that sequence ``index`` failed with ``exc``
        (a trajectory file an earlier, killed run of the trial left for it goes) and return
        True: the trial goes on without it. False (the caller re-raises) under ``failures:
        trial``, for a time limit (``TrialTimeout``) and for the machinery's failure."""
        if self.job.failures != "sequence" or isinstance(exc, TrialTimeout | InfrastructureError):
            return False
        name = self.job.sequences[index][0]
        self.why[index] = one_line(exc)
        trajectory_path(self.job.out_dir, self.job.algorithm, name, self.job.trial).unlink(
            missing_ok=True)
        return True

    def objective(self, rte: Mapping[str, float]) -> float:
        """The trial's objective [%]: the mean of the finished sequences' ``rte`` when none
        failed (the rule ``failures: trial`` computes), else the mean over every sequence with
        each failed one at ``penalty_pct``. OdometryError naming them when none finished."""
        if not self.why:
            return float(np.mean(list(rte.values())))
        if not rte:
            raise OdometryError(f"every sequence failed ({self._names()}): {self._details()}")
        return float(np.mean([*rte.values(), *(self.job.penalty_pct for _ in self.why)]))

    def text(self, before: str = "") -> str:
        """``before`` (a pruned trial's reason) and the failed sequences, names first, then why
        each failed: the trial's one-line ``error`` (at most MAX_ERROR_CHARS); ``before`` alone
        when none failed."""
        if not self.why:
            return before
        text = (f"{len(self.why)} of {len(self.job.sequences)} sequences failed, each at the "
                f"penalty {self.job.penalty_pct:g} % ({self._names()}): {self._details()}")
        line = f"{before}; {text}" if before else text
        return " ".join(line.split())[:MAX_ERROR_CHARS]

    def _names(self) -> str:
        return ", ".join(self.job.sequences[s][0] for s in sorted(self.why))

    def _details(self) -> str:
        return "; ".join(f"{self.job.sequences[s][0]}: {self.why[s]}" for s in sorted(self.why))


def _curve(job: TrialJob, points: list[Any], gts: list[NDArray[np.float64]],
           ests: Sequence[NDArray[np.float64] | None], failed: SequenceFailures, ok: bool,
           posted: Sequence[float] | None = None) -> tuple[float, ...]:
    """The values at the checkpoints the trial records (``TrialResult.curve``: the percentile
    pruner's reference for later trials, and what a resume restores from the stored
    trajectories, ``StudyPruner.restore``). With no failed sequence: its values, as it ran.
    With some (``failures: sequence``), what the stored trajectories give, which hold none of
    a failed sequence: an ok trial counts each failed sequence at the penalty at every
    checkpoint where it had started, a pruned one's curve ends before the first such
    checkpoint; but successive halving keeps the values the trial ``posted`` at its rungs
    (the rung board, which later trials read, is never rewritten)."""
    from pipeline.tuning.pruning import curve_of

    if not failed.why:
        return curve_of(points, gts, ests, job.sequence_lengths_m, job.scored_only)
    if posted is not None and job.rungs is not None:
        return tuple(posted)
    kept = [None if s in failed.why else est for s, est in enumerate(ests)]
    return curve_of(points, gts, kept, job.sequence_lengths_m, job.scored_only,
                    failed.why if ok else (), job.penalty_pct)


def _score(job: TrialJob, name: str, gt: NDArray[np.float64], traj: Trajectory) -> float:
    """RTE [%] of a finished, checked sequence run; its trajectory written. OdometryError for a
    jump or a run with no segment to score."""
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.trajectory import write_trajectory

    check_jump(traj, job.jump_limit_of(name))
    length_m = job.length_of(name)
    rte = mean_rte_pct(gt, traj.T_world_lidar, length_m)
    if not np.isfinite(rte):
        raise OdometryError(f"{name}: no segment of {length_m} m to score")
    out = trajectory_path(job.out_dir, job.algorithm, name, job.trial)
    write_trajectory(out, traj, _metadata(job, name, out))
    return rte


class SequenceRun:
    """One sequence of a trial, run a frame at a time by a streaming adapter (from the decoded
    scans, or read and decoded ahead from its MCAP)."""

    def __init__(self, adapter: Adapter, params: dict[str, float], path: str,
                 cached: list[Scan] | None, stack: contextlib.ExitStack) -> None:
        from pipeline.io_utils import prefetch
        from pipeline.odometry import make_schedule
        from pipeline.odometry.base import stream_poses
        from pipeline.sequence import SequenceReader

        self.path = path
        scans: Iterable[Scan]
        if cached is not None:
            scans, self.stamps_ns = cached, np.array([sc.stamp_ns for sc in cached], np.int64)
        else:
            reader = stack.enter_context(SequenceReader(path))
            self.stamps_ns = np.asarray(reader.stamps_ns, np.int64)
            scans = stack.enter_context(contextlib.closing(prefetch(reader)))
        schedule = make_schedule(adapter, params, len(self.stamps_ns), path)
        self._steps = stream_poses(adapter.start, scans, schedule)  # type: ignore[attr-defined]
        stack.callback(self._steps.close)
        self.frames: list[int] = []
        self.poses: list[NDArray[np.float64]] = []
        self.seconds = 0.0  # wall time in the odometry (and decoding) so far

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def finished(self) -> bool:
        return len(self.poses) == len(self.stamps_ns)

    def advance(self, frame: int) -> None:
        """Run up to and including ``frame``."""
        import time

        t0 = time.perf_counter()
        try:
            while len(self.poses) <= frame:
                scan, pose = next(self._steps)
                self.frames.append(scan.frame)
                self.poses.append(pose)
        finally:
            self.seconds += time.perf_counter() - t0

    def estimate(self) -> NDArray[np.float64] | None:
        """T_world_lidar (n, 4, 4) of the frames run so far; None before the first."""
        return np.stack(self.poses) if self.poses else None

    def trajectory(self) -> Trajectory:
        """The frames run so far as a Trajectory (at least one)."""
        n = len(self.poses)
        return Trajectory(np.array(self.frames, np.int32), self.stamps_ns[:n].copy(),
                          np.stack(self.poses))


def _run_stepped(job: TrialJob, adapter: Adapter, scans: Mapping[str, list[Scan]],
                 gts: list[NDArray[np.float64]], points: list[Any],
                 on_wait: Callable[[float], None] | None = None) -> dict[str, Any]:
    """``job`` run checkpoint by checkpoint: every sequence to the checkpoint's frame, then
    the check (``_threshold``); a sequence that has run its last frame is checked and scored
    at once. Pruned: the trajectories run so far are written. Under ``failures: sequence`` a
    sequence that fails (while it runs, or at its check) runs no further and counts at the
    penalty in the trial's value from the next checkpoint on (``value_at``'s ``failed``)."""
    from pipeline.odometry import check_trajectory
    from pipeline.trajectory import write_trajectory
    from pipeline.tuning.pruning import Pruned, value_at

    rte: dict[str, float] = {}
    failed = SequenceFailures(job)
    with contextlib.ExitStack() as stack:
        runs = [SequenceRun(adapter, job.params, path, scans.get(path), stack)
                for _, path in job.sequences]
        ends = [len(gt) - 1 for gt in gts]

        def reach(frames: Sequence[int]) -> None:
            for s, (run, frame) in enumerate(zip(runs, frames, strict=True)):
                if s in failed.why:
                    continue
                try:
                    run.advance(frame)
                except Exception as exc:
                    if not failed.absorb(s, exc):
                        raise

        def finish() -> None:
            for s, ((name, _), run, gt) in enumerate(zip(job.sequences, runs, gts, strict=True)):
                if run.finished and name not in rte and s not in failed.why:
                    try:
                        traj = run.trajectory()
                        check_trajectory(traj, run.stamps_ns, f"{adapter.name} on {run.path}")
                        rte[name] = _score(job, name, gt, traj)
                    except Exception as exc:
                        if not failed.absorb(s, exc):
                            raise

        posted: list[float] = []
        try:
            for index, point in enumerate(points):
                reach(point.frames)
                value = value_at(point, gts, [r.estimate() for r in runs],
                                 job.sequence_lengths_m, scored_only=job.scored_only,
                                 failed=failed.why, penalty_pct=job.penalty_pct)
                posted.append(value)
                limit = _threshold(job, index, posted, on_wait)
                if limit is not None and value > limit:  # a NaN value never is
                    raise Pruned(index, value, limit)
                finish()
            for s in range(len(runs)):  # the last rung: every sequence to its end, in order
                reach([*ends[:s + 1], *(-1 for _ in ends[s + 1:])])
                finish()
        except Pruned as stop:
            ests = [r.estimate() for r in runs]
            for s, ((name, _), run) in enumerate(zip(job.sequences, runs, strict=True)):
                if len(run) and name not in rte and s not in failed.why:
                    out = trajectory_path(job.out_dir, job.algorithm, name, job.trial)
                    write_trajectory(out, run.trajectory(), _metadata(job, name, out))
            why = (f"pruned at {_where(job, runs, points[stop.index], failed.why)}: running "
                   f"RTE {stop.value:.4g} % above {stop.threshold:.4g} %")
            return {"status": "pruned", "objective": stop.value, "rte_pct": rte,
                    "odometry_s": sum(r.seconds for r in runs),
                    "curve": _curve(job, points, gts, ests, failed, False, posted),
                    "error": failed.text(why)}
        ests = [r.estimate() for r in runs]
        odometry_s = sum(r.seconds for r in runs)
    return {"status": "ok", "objective": failed.objective(rte), "rte_pct": rte,
            "odometry_s": odometry_s, "error": failed.text(),
            "curve": _curve(job, points, gts, ests, failed, True, posted)}


def _threshold(job: TrialJob, index: int, posted: list[float],
               on_wait: Callable[[float], None] | None) -> float | None:
    """The threshold at checkpoint ``index``, where the trial's values so far are ``posted``:
    the job's own (the percentile pruner), or, with a rung board, the rung's over the earlier
    trials, once this trial's value is posted there (``RungBoard.threshold``: it may wait, at
    most twice the trial's time limit, which leaves the wait out; a NaN value, which no
    threshold stops, does not wait)."""
    if job.rungs is None:
        return job.thresholds[index]
    job.rungs.post(job.trial, posted)
    if not math.isfinite(posted[-1]):
        return None
    wait_s = None if job.limit_s is None else 2 * job.limit_s
    return job.rungs.threshold(job.trial, index, job.eta, wait_s, on_wait)


def _metadata(job: TrialJob, name: str, out: Path) -> dict[str, str]:
    """The footer of the trajectory ``out`` of sequence ``name``: its sequence MCAP by a path
    relative to the trajectory's folder (``adaptune export`` finds it from anywhere), the trial
    and its parameters."""
    path = dict(job.sequences)[name]
    return {"algorithm": job.algorithm,
            "sequence": os.path.relpath(Path(path).resolve(), Path(out).resolve().parent),
            "trial": str(job.trial), "params_json": json.dumps(job.params, sort_keys=True)}


def _where(job: TrialJob, runs: list[SequenceRun], point: Any,
           failed: Collection[int] = ()) -> str:
    """Where a trial stopped: the sequences it was running ("seq_a frame 12, seq_b frame 9"),
    ``failed`` ones (by index) left out, or the last one it finished."""
    running = [f"{name} frame {frame}" for s, ((name, _), run, frame)
               in enumerate(zip(job.sequences, runs, point.frames, strict=True))
               if frame >= 0 and not run.finished and s not in failed]
    if running:
        return ", ".join(running)
    last = max(s for s, frame in enumerate(point.frames) if frame >= 0)
    return f"{job.sequences[last][0]} frame {point.frames[last]}"


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
