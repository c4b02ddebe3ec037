"""What a worker process keeps between trials, in one object: ``WorkerState``.

A worker (a process-pool process, a Dask worker, or a trial server) runs many trials of the
same study. It keeps:
- the scan cache: the study's sequences decoded once (only these; skipped when they exceed
  ``scan_cache_limit_bytes()``), so reading the MCAPs is paid once, not once per trial; and
  their ground truth, read once;
- the warmed adapter: one adapter instance per (adapter, options, sequences) on which the
  optional ``warm(scans)`` ran (``ndt`` keeps its downsampled source clouds there);
- its idle trial servers (``pipeline.tuning.server``), one per concurrent caller, for trials
  with a time limit.

``run_trial(job)`` is the top-level, picklable function executors run: it uses this process's
state (made on first use). Tests make their own ``WorkerState`` and call ``state.run(job)``.

Time limit: with ``time_limit_s`` set (per sequence; a joint trial gets the sum), the trial runs
in a trial server and is SIGKILLed when it outlives the limit, so even a hang inside C code
ends; the server holds its own WorkerState. With ``time_limit_s=None`` the trial runs in the
calling process, with this state's cache.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from pipeline.errors import InfrastructureError, OdometryError
from pipeline.odometry.base import Adapter
from pipeline.odometry.registry import build_adapter
from pipeline.tuning.job import (
    TrialJob,
    TrialResult,
    evaluate_trial,
    one_line,
    remove_trajectories,
)

log = logging.getLogger(__name__)


SCAN_CACHE_MAX_BYTES = 8 << 30
"""The most decoded sequences one worker keeps, whatever its memory."""


def scan_cache_limit_bytes(share_bytes: int | None = None,
                           machine_bytes: int | None = None) -> int:
    """Decoded sequences [bytes] a worker keeps at most (the MCAP chunks' uncompressed size): a
    quarter of the machine's memory, half of the worker's share of it (so that the caches of
    all the workers together hold half the machine at most), at most ``SCAN_CACHE_MAX_BYTES``;
    1 GiB where the memory is unknown. Defaults: ``pipeline.executor.worker_memory_bytes`` (a
    pool worker's share; the machine's in any other process) and ``machine_memory_bytes``."""
    from pipeline.executor import machine_memory_bytes, worker_memory_bytes

    share = worker_memory_bytes() if share_bytes is None else share_bytes
    machine = machine_memory_bytes() if machine_bytes is None else machine_bytes
    if not share or not machine:
        return 1 << 30
    return int(min(machine // 4, share // 2, SCAN_CACHE_MAX_BYTES))


def study_key(job: TrialJob) -> tuple[Any, ...]:
    """What a cache, a warmed adapter and a trial server serve: sequences, adapter, options,
    space."""
    return (tuple(p for _, p in job.sequences), job.adapter,
            json.dumps(job.adapter_options, sort_keys=True, default=str),
            json.dumps(job.space, sort_keys=True))


class WorkerState:
    """The scan cache, the warmed adapter and the idle trial servers of one worker process.

    Thread-safe: Dask workers run several tasks at once; each running trial with a time limit
    has a server of its own.
    """

    def __init__(self, cache_limit_bytes: int | None = None) -> None:
        self.scan_cache_limit_bytes = (scan_cache_limit_bytes() if cache_limit_bytes is None
                                       else cache_limit_bytes)
        self.scans: dict[str, list[Any]] = {}
        self.truths: dict[str, Any] = {}  # ground truth by path, read once
        self.adapter: tuple[tuple[Any, ...], Adapter] | None = None
        self.idle: list[Any] = []  # TrialServer
        self.on_wait: Callable[[float], None] | None = None  # a server's: tell the parent
        self._lock = threading.Lock()

    # -- running a trial -------------------------------------------------------------------

    def run(self, job: TrialJob) -> TrialResult:
        """Run ``job``: an ok, pruned, failed (odometry) or lost (infrastructure) TrialResult,
        never an exception."""
        t0 = time.perf_counter()
        try:
            if job.limit_s is None:
                out = self.evaluate(job)
            else:
                out = self._run_in_server(job, job.limit_s)
        except InfrastructureError as exc:  # lost: run again, its rung posts anew
            remove_trajectories(job)
            return TrialResult(job.trial, "lost", one_line(exc), math.nan,
                               time.perf_counter() - t0, job.seed, dict(job.params))
        except Exception as exc:
            remove_trajectories(job)
            if job.rungs is not None:
                job.rungs.end(job.trial)
            return TrialResult(job.trial, "failed", one_line(exc), job.penalty_pct,
                               time.perf_counter() - t0, job.seed, dict(job.params))
        if job.rungs is not None:
            job.rungs.end(job.trial, out["curve"])
        return TrialResult(job.trial, out["status"], out["error"], out["objective"],
                           time.perf_counter() - t0, job.seed, dict(job.params), out["rte_pct"],
                           out["odometry_s"], tuple(out["curve"]))

    def evaluate(self, job: TrialJob) -> dict[str, Any]:
        """``evaluate_trial`` in this process, with the scan cache and the warmed adapter (a
        trial server's state tells its parent how long the trial waited at its rungs)."""
        adapter = self.warm(job)
        return evaluate_trial(job, adapter, self.scans, self.truths, self.on_wait)

    def outcome(self, job: TrialJob) -> tuple[str, Any]:
        """("ok", ``self.evaluate(job)``) or ("error", the exception in one line)."""
        try:
            return ("ok", self.evaluate(job))
        except BaseException as exc:
            return ("error", one_line(exc))

    def _run_in_server(self, job: TrialJob, limit_s: float) -> dict[str, Any]:
        server = self._checkout(study_key(job))
        kind, payload = server.run(job, limit_s)  # raises when the server had to go
        self._checkin(server)
        if kind != "ok":
            raise OdometryError(payload)
        return payload  # type: ignore[no-any-return]

    # -- trial servers ---------------------------------------------------------------------

    def _checkout(self, key: tuple[Any, ...]) -> Any:
        """An idle live server for ``key`` or a new one; idle servers of other keys stop."""
        from pipeline.tuning.server import TrialServer

        with self._lock:
            keep: list[Any] = []
            stale: list[Any] = []
            for server in self.idle:
                (keep if server.key == key and server.alive() else stale).append(server)
            found = keep.pop() if keep else None
            self.idle = keep
        for server in stale:
            server.stop()
        return found if found is not None else TrialServer(key)

    def _checkin(self, server: Any) -> None:
        with self._lock:
            self.idle.append(server)

    def close(self) -> None:
        """Stop every idle server (running ones end with their trial)."""
        with self._lock:
            servers, self.idle = self.idle, []
        for server in servers:
            server.stop()

    # -- scan cache and warm adapter -------------------------------------------------------

    def warm(self, job: TrialJob) -> Adapter:
        """The adapter for ``job``, warmed over its sequences' decoded scans (once per key).

        The sequences are decoded into the cache unless they are too large (then every trial
        reads its MCAP); the adapter's optional ``warm(scans)`` precomputes what depends on the
        scans alone. Adapters must not modify the scans they are given (trials share them).
        """
        key = study_key(job)
        with self._lock:
            if self.adapter is not None and self.adapter[0] == key:
                return self.adapter[1]
            adapter = build_adapter(job.adapter, job.adapter_options, job.space)
            paths = list(key[0])
            self._fill_cache(paths)
            warm = getattr(adapter, "warm", None)
            if warm is not None and all(p in self.scans for p in paths):
                warm([scan for p in paths for scan in self.scans[p]])
            self.adapter = (key, adapter)
            return adapter

    def warm_quietly(self, job: TrialJob) -> None:
        """``warm``, errors left to the trial itself (which then reports them)."""
        with contextlib.suppress(Exception):
            self.warm(job)

    def _fill_cache(self, paths: list[str]) -> None:
        """Decode ``paths`` into the cache (and drop other sequences), if they fit."""
        from pipeline.sequence import SequenceReader

        for stale in set(self.scans) - set(paths):
            del self.scans[stale]
        for stale in set(self.truths) - set(paths):
            del self.truths[stale]
        if sum(decoded_bytes(p) for p in paths) > self.scan_cache_limit_bytes:
            log.info("scan cache: %s too large to keep decoded; every trial reads them", paths)
            self.scans.clear()
            return
        for p in paths:
            if p not in self.scans:
                with SequenceReader(p) as reader:
                    self.scans[p] = list(reader)


def decoded_bytes(path: str) -> int:
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


_PROCESS_STATE: list[WorkerState] = []
"""This process's WorkerState (made by the first ``run_trial``)."""


def process_state() -> WorkerState:
    """The WorkerState of this process, made on first use."""
    if not _PROCESS_STATE:
        _PROCESS_STATE.append(WorkerState())
    return _PROCESS_STATE[0]


def run_trial(job: TrialJob) -> TrialResult:
    """Run ``job`` with this process's WorkerState (the function executors are given)."""
    return process_state().run(job)


def serve(fd: int, parent_pid: int) -> None:
    """A trial server's loop (``pipeline.tuning.server``, in the child): warm for the first
    job, answer "ready", then answer every job with ``WorkerState.outcome`` (sending
    (WAITED, seconds) while it runs when it waits at a rung); returns when the parent closes
    the socket."""
    import signal
    from multiprocessing.connection import Connection

    from pipeline.lifetime import die_with_parent, exit_on_hangup
    from pipeline.tuning.server import WAITED

    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_on_hangup(fd)
    conn = Connection(fd)
    state = WorkerState()
    state.on_wait = lambda seconds: conn.send((WAITED, seconds))
    first = True
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if first:
            state.warm_quietly(job)
            conn.send("ready")
            first = False
        conn.send(state.outcome(job))
