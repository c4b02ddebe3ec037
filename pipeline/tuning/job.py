"""One trial: run an adapter with fixed parameters over one or more sequences, score, write.

``run_trial(job)`` is the top-level, picklable function the executor runs. It never raises for a
failing odometry: an exception, a non-finite pose, lost frames, an implausible jump (a
frame-to-frame translation above ``jump_limit_m``) or a run past its time limit make a *failed*
result whose objective is ``penalty_pct`` (a fixed number, so that a resumed or repeated run
sees the same history) and whose ``error`` is one line of text.

Time limit: with ``time_limit_s`` set (per sequence; a joint trial gets the sum), the trial runs
in a child process and is SIGKILLed when it outlives the limit, so even a hang inside C code
ends. The child is a ``TrialServer`` forked from the worker once it has decoded the sequences
(the scan cache), running the study's trials one after another, or a ``forkserver`` process per
trial in Dask workers; see ``_run_in_child``.
With ``time_limit_s=None`` the trial runs in the calling process (with the scan cache).
The child writes the trajectory Parquet files (atomically) and sends back a small result.
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError, OdometryError, TrialTimeout
from pipeline.odometry.base import Adapter
from pipeline.trajectory import Trajectory

log = logging.getLogger(__name__)

MAX_ERROR_CHARS = 400


@dataclass(frozen=True)
class TrialJob:
    """Everything a worker needs for one trial (plain data, picklable).

    adapter: a registry name (``ndt``) or ``module:factory`` (``(**options) -> Adapter``).
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


@dataclass(frozen=True)
class TrialResult:
    """Outcome of one trial; objective: mean translational RTE [%] (over sequences) or penalty."""

    trial: int
    status: str  # 'ok' | 'failed'
    error: str
    objective: float
    wall_time_s: float
    seed: int
    params: dict[str, float]
    rte_pct: dict[str, float] = field(default_factory=dict)
    odometry_s: float = 0.0


def resolve_adapter(ref: str, options: Mapping[str, Any] | None = None) -> Adapter:
    """The adapter named ``ref`` in the registry, or built by the factory ``module:attr``."""
    options = dict(options or {})
    if ":" in ref:
        import importlib

        module, attr = ref.split(":", 1)
        return getattr(importlib.import_module(module), attr)(**options)  # type: ignore[no-any-return]
    from pipeline.odometry.registry import get_adapter

    return get_adapter(ref, **options)


def trajectory_path(out_dir: str | Path, algorithm: str, sequence: str, trial: int) -> Path:
    """``<OUT>/trajectories/algorithm=<A>/sequence=<S>/trial=<N>/trajectory.parquet``."""
    return (Path(out_dir) / "trajectories" / f"algorithm={algorithm}" / f"sequence={sequence}"
            / f"trial={trial}" / "trajectory.parquet")


def run_trial(job: TrialJob) -> TrialResult:
    """Run ``job``; a failed TrialResult (never an exception) when the odometry fails."""
    t0 = time.perf_counter()
    try:
        if job.time_limit_s is None:
            warm_scan_cache(job)
            out = evaluate_trial(job)
        else:
            out = _run_in_child(job, job.time_limit_s * len(job.sequences))
    except Exception as exc:
        _remove_trajectories(job)
        return TrialResult(job.trial, "failed", _one_line(exc), job.penalty_pct,
                           time.perf_counter() - t0, job.seed, dict(job.params))
    return TrialResult(job.trial, "ok", "", out["objective"], time.perf_counter() - t0, job.seed,
                       dict(job.params), out["rte_pct"], out["odometry_s"])


def evaluate_trial(job: TrialJob) -> dict[str, Any]:
    """Run, check, score and write every sequence of ``job``; raises on any failure.

    Returns {"objective": mean RTE [%] over sequences, "rte_pct": {sequence: RTE}, "odometry_s"}.
    ``pipeline.odometry.run_sequence`` checks frames, stamps, finiteness; ``check_jump`` jumps.
    """
    from pipeline.evaluation.rte import mean_rte_pct
    from pipeline.odometry import check_trajectory, make_schedule, run_sequence
    from pipeline.trajectory import write_trajectory

    adapter = resolve_adapter(job.adapter, job.adapter_options)
    rte: dict[str, float] = {}
    odometry_s = 0.0
    for name, path in job.sequences:
        gt = load_ground_truth(path)
        scans = _SCANS.get(path)
        t0 = time.perf_counter()
        if scans is None or getattr(adapter, "accepts_time_limit", False):
            traj = run_sequence(adapter, path, job.params, job.time_limit_s)
        else:  # the scans decoded once by this worker (see warm_scan_cache)
            traj = adapter.run(scans, make_schedule(adapter, job.params, len(scans), path))
            stamps_ns = np.array([sc.stamp_ns for sc in scans])
            check_trajectory(traj, stamps_ns, f"{adapter.name} on {path}")
        odometry_s += time.perf_counter() - t0
        check_jump(traj, job.jump_limit_m)
        rte[name] = mean_rte_pct(gt, traj.T_world_lidar, job.length_m)
        if not np.isfinite(rte[name]):
            raise OdometryError(f"{name}: no segment of {job.length_m} m to score")
        write_trajectory(trajectory_path(job.out_dir, job.algorithm, name, job.trial), traj, {
            "algorithm": job.algorithm, "sequence": name, "trial": str(job.trial),
            "params_json": json.dumps(job.params, sort_keys=True)})
    objective = float(np.mean(list(rte.values())))
    return {"objective": objective, "rte_pct": rte, "odometry_s": odometry_s}


def load_ground_truth(path: str | Path) -> NDArray[np.float64]:
    """(N, 4, 4) ground-truth T_world_lidar of a sequence MCAP; InputError when it has none."""
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        gt = reader.ground_truth()
    if gt is None:
        raise InputError(f"{path}: no ground truth to score trials against")
    return gt


def check_jump(traj: Trajectory, jump_limit_m: float) -> None:
    """OdometryError when a frame-to-frame translation exceeds ``jump_limit_m`` [m]."""
    if len(traj) > 1:
        step_m = np.linalg.norm(np.diff(traj.T_world_lidar[:, :3, 3], axis=0), axis=1)
        k = int(np.argmax(step_m))
        if not step_m[k] <= jump_limit_m:
            raise OdometryError(f"implausible jump of {step_m[k]:.3g} m at frame {k + 1} "
                                f"(jump_limit_m={jump_limit_m})")


# -- scan cache ----------------------------------------------------------------------------

def _scan_cache_limit_bytes() -> int:
    """A quarter of the machine's memory, at most 8 GiB (1 GiB where it cannot be read)."""
    try:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 1 << 30
    return int(min(physical // 4, 8 << 30))


SCAN_CACHE_LIMIT_BYTES = _scan_cache_limit_bytes()
"""Decoded sequences a worker keeps in memory at most (the MCAP chunks' uncompressed size)."""

_SCANS: dict[str, list[Any]] = {}


def warm_scan_cache(job: TrialJob) -> None:
    """Decode the job's sequences once per worker process and keep them (only these).

    Every trial of a study reads the same MCAP; a trial child forked from this process inherits
    the decoded scans (copy-on-write), so reading the MCAP is paid once, not once per trial.
    Skipped when the sequences are too large (then each trial reads its MCAP). Then the
    adapter's optional ``warm(scans)`` precomputes what depends on the scans alone.
    Adapters must not modify the scans they are given (in-process runs share the cache).
    """
    from pipeline.sequence import SequenceReader

    paths = [p for _, p in job.sequences]
    for stale in set(_SCANS) - set(paths):
        del _SCANS[stale]
    if sum(decoded_bytes(p) for p in paths) > SCAN_CACHE_LIMIT_BYTES:
        log.info("scan cache: %s too large to keep decoded; every trial reads them", paths)
        _SCANS.clear()
        return
    for p in paths:
        if p not in _SCANS:
            with SequenceReader(p) as reader:
                _SCANS[p] = list(reader)
    _warm_adapter(job, paths)


def decoded_bytes(path: str | Path) -> int:
    """Uncompressed size [bytes] of a sequence MCAP's chunks: about its decoded size."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as fh:
            summary = make_reader(fh).get_summary()
    except Exception:  # unreadable: the trial itself reports it
        return 0
    if summary is None:
        return 0
    return sum(ci.uncompressed_size for ci in summary.chunk_indexes)


_WARMED: list[Any] = []
"""What the adapter was last warmed for: [(adapter, options, paths, scan lists)]."""


def _warm_adapter(job: TrialJob, paths: list[str]) -> None:
    """Let the adapter precompute what depends only on the cached scans (``Adapter.warm``,
    optional), once per adapter, options and set of scans."""
    scans = [_SCANS[p] for p in paths]
    state = (job.adapter, job.adapter_options, paths, scans)
    if _WARMED and _WARMED[0][:3] == state[:3] and all(
            a is b for a, b in zip(_WARMED[0][3], scans, strict=True)):
        return
    adapter = resolve_adapter(job.adapter, job.adapter_options)
    warm = getattr(adapter, "warm", None)
    if warm is not None:
        warm([scan for seq in scans for scan in seq])
    _WARMED[:] = [state]


# -- the child process ---------------------------------------------------------------------

_PRELOADED: set[str] = set()
_SERVER: list[TrialServer] = []
"""This worker's trial server (at most one), for the scans cached now."""


def _run_in_child(job: TrialJob, limit_s: float) -> dict[str, Any]:
    """``evaluate_trial(job)`` in a child process, killed after ``limit_s`` seconds.

    A process-pool worker (any process that is not a Dask worker) decodes the scans once
    (``warm_scan_cache``) and forks a ``TrialServer`` that runs the study's trials one after
    another. A Dask worker, whose task threads run beside the one that would fork, starts every
    trial from a ``forkserver`` instead (preloaded modules; each trial reads its MCAP).
    (A helper thread such as tqdm's monitor does not make a process a Dask worker.)
    """
    if multiprocessing.current_process().daemon:
        raise OdometryError("cannot enforce the time limit in a daemonic worker process; "
                            "start Dask workers with DASK_DISTRIBUTED__WORKER__DAEMON=False")
    if _in_dask_worker():
        kind, payload = _run_in_forkserver(job, limit_s)
    else:
        with contextlib.suppress(Exception):  # unreadable input: the child reports it
            warm_scan_cache(job)
        kind, payload = _trial_server(job).run(job, limit_s)
    if kind != "ok":
        raise OdometryError(payload)
    return payload  # type: ignore[no-any-return]


class TrialServer:
    """A child forked from this worker after the scan cache is filled: it runs trials one after
    another, so fork, page faults and module state are paid once per study, not per trial.
    A trial that outlives its limit or kills the process takes the server down with it; the
    next trial forks a new one. The worker itself never runs odometry, so no OpenMP or other
    thread-pool state is forked."""

    def __init__(self, key: tuple[Any, ...]) -> None:
        ctx = multiprocessing.get_context("fork")
        self.key = key
        self.conn, child_end = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_serve, args=(child_end, self.conn), name="trials",
                                daemon=True)
        self.proc.start()
        child_end.close()

    def run(self, job: TrialJob, limit_s: float) -> tuple[str, Any]:
        """("ok", result) or ("error", text) of ``job``; TrialTimeout or OdometryError when the
        process had to be killed or died."""
        self.conn.send(job)
        if not self.conn.poll(limit_s):
            self.stop()
            raise TrialTimeout(f"time limit of {limit_s:g} s exceeded (trial process killed)")
        try:
            return self.conn.recv()  # type: ignore[no-any-return]
        except EOFError:
            self.proc.join(5.0)
            code = self.proc.exitcode
            self.stop()
            raise OdometryError(f"trial process died (exit code {code})") from None

    def alive(self) -> bool:
        return self.proc.is_alive()

    def stop(self) -> None:
        """Kill the process (if still running) and forget it."""
        self.conn.close()
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join()
        if self in _SERVER:
            _SERVER.remove(self)


def _trial_server(job: TrialJob) -> TrialServer:
    """This worker's server for ``job``'s sequences and adapter, (re)started when needed."""
    key = (tuple(p for _, p in job.sequences), job.adapter,
           json.dumps(job.adapter_options, sort_keys=True, default=str))
    for server in list(_SERVER):
        if server.key == key and server.alive():
            return server
        server.stop()
    _SERVER.append(TrialServer(key))
    return _SERVER[0]


def _serve(conn: Any, parent_end: Any) -> None:
    """The trial server's loop: receive a TrialJob, send ("ok", out) or ("error", text)."""
    parent_end.close()
    while True:
        try:
            job = conn.recv()
        except EOFError:  # the worker is gone
            return
        conn.send(_outcome(job))


def _in_dask_worker() -> bool:
    """True when this code runs in a task of a Dask distributed worker."""
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return False
    try:
        distributed.get_worker()
    except ValueError:
        return False
    return True


def _forkserver(job: TrialJob) -> multiprocessing.context.ForkServerContext:
    """The forkserver context, its preload list set once (the adapter's module among them)."""
    ctx = multiprocessing.get_context("forkserver")
    if not _PRELOADED:
        modules = ["pipeline.tuning.job", "pipeline.evaluation.rte", "pipeline.odometry"]
        with contextlib.suppress(Exception):  # the child reports the error as a failed trial
            modules.append(type(resolve_adapter(job.adapter, job.adapter_options)).__module__)
        ctx.set_forkserver_preload(modules)  # type: ignore[attr-defined]
        _PRELOADED.update(modules)
    return ctx


def _child_main(job: TrialJob, conn: Any) -> None:
    """Entry point of a one-trial process: evaluate and send ("ok", out) or ("error", text)."""
    conn.send(_outcome(job))
    conn.close()


def _outcome(job: TrialJob) -> tuple[str, Any]:
    """("ok", ``evaluate_trial(job)``) or ("error", the exception in one line), for the pipe."""
    try:
        return ("ok", evaluate_trial(job))
    except BaseException as exc:
        return ("error", _one_line(exc))


def _run_in_forkserver(job: TrialJob, limit_s: float) -> tuple[str, Any]:
    """One trial in a process started by the forkserver, killed after ``limit_s`` seconds."""
    _SCANS.clear()
    ctx = _forkserver(job)
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child_main, args=(job, send), name=f"trial-{job.trial}")
    proc.start()
    send.close()
    try:
        if not recv.poll(limit_s):
            proc.kill()
            raise TrialTimeout(f"time limit of {limit_s:g} s exceeded (trial process killed)")
        try:
            return recv.recv()  # type: ignore[no-any-return]
        except EOFError:
            proc.join(5.0)
            raise OdometryError(f"trial process died (exit code {proc.exitcode})") from None
    finally:
        recv.close()
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join()


def _one_line(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, OdometryError) else f"{type(exc).__name__}: {exc}"
    text = " ".join(text.split())
    return text[:MAX_ERROR_CHARS]


def _remove_trajectories(job: TrialJob) -> None:
    """Drop trajectory files of a failed trial (e.g. left by an earlier, killed run)."""
    for name, _ in job.sequences:
        trajectory_path(job.out_dir, job.algorithm, name, job.trial).unlink(missing_ok=True)
