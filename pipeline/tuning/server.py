"""The trial server: a child process that runs a study's trials one after another, killed at a
trial's time limit.

``TrialServer(key)`` starts ``python -c <boot>`` with ``subprocess`` (not ``multiprocessing``:
it works in daemonic processes such as plain Dask workers, and never forks a threaded process),
connected by a socket pair over which jobs and results travel as pickles (our own two
processes, nothing stored). The child (``pipeline.tuning.worker.serve``) imports the parent's
``sys.path``, decodes the sequences once and warms the adapter (its own ``WorkerState``), then
answers each job with
("ok", result) or ("error", one line), after a (``WAITED``, seconds) for every pause it
made at a rung waiting for earlier trials, which the time limit leaves out. It ends with its
parent: ``PR_SET_PDEATHSIG`` and a thread watching the socket (``pipeline.lifetime``); it
ignores SIGINT, so that Ctrl-C is handled by the main process alone.

A trial that outlives its limit takes the server down (SIGKILL); the next trial starts a new
one. A server that dies is classified by how (``died``): killed by a signal from outside
(SIGKILL, SIGTERM, SIGINT, SIGHUP: the OOM killer, an operator) is an InfrastructureError, the
trial is lost and retried; anything else (an exit code, a segfault) is the trial's own failure.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection
from typing import Any

from pipeline.errors import InfrastructureError, OdometryError, TrialTimeout
from pipeline.tuning.job import TrialJob

LOST_SIGNALS = frozenset({signal.SIGKILL, signal.SIGTERM, signal.SIGINT, signal.SIGHUP})
"""Signals that end a trial process from outside: the trial is lost (retried), not failed."""

WARM_LIMIT_S = 600.0
"""Time a new server gets to start, decode the sequences and warm the adapter [s] (on top of
the trial's own limit, which covers the odometry alone)."""

WAITED = "waited"
"""A trial server's message (WAITED, seconds) while a trial runs: it waited that long at a rung
for earlier trials (``pipeline.tuning.rung_board``); its time limit leaves the wait out."""

_BOOT = ("import sys, json; sys.path[:] = json.loads(sys.argv[3]); "
         "from pipeline.tuning.worker import serve; serve(int(sys.argv[1]), int(sys.argv[2]))")


class TrialServer:
    """The parent's handle on one trial server process, for the sequences and adapter ``key``."""

    def __init__(self, key: tuple[Any, ...]) -> None:
        self.key = key
        parent_end, child_end = socket.socketpair()
        fd = child_end.fileno()
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", _BOOT, str(fd), str(os.getpid()), json.dumps(sys.path)],
                pass_fds=(fd,), stdin=subprocess.DEVNULL)
        except OSError as exc:
            parent_end.close()
            raise InfrastructureError(f"cannot start a trial process ({exc})") from None
        finally:
            child_end.close()
        self.conn = Connection(parent_end.detach())
        self._warm = True  # the first trial also waits for decoding and warming

    def run(self, job: TrialJob, limit_s: float) -> tuple[str, Any]:
        """("ok", result) or ("error", text) of ``job``. TrialTimeout past ``limit_s`` (the
        server is killed), or the error ``died`` gives when the server ended."""
        try:
            self.conn.send(job)
            if self._warm:  # the server says "ready" once its scans are decoded
                self._expect("ready", WARM_LIMIT_S + limit_s)
                self._warm = False
            return self._answer(limit_s)
        except (EOFError, OSError):
            raise self.died() from None

    def _answer(self, limit_s: float) -> tuple[str, Any]:
        """The trial's answer within ``limit_s`` of odometry: the time it reports waiting at
        its rungs for earlier trials ((WAITED, seconds) messages) extends the deadline."""
        deadline = time.monotonic() + limit_s
        while True:
            if not self.conn.poll(max(deadline - time.monotonic(), 0.0)):
                self.stop()
                raise TrialTimeout(f"time limit of {limit_s:g} s exceeded (trial process killed)")
            answer = self.conn.recv()
            if isinstance(answer, tuple) and answer[0] == WAITED:
                deadline += float(answer[1])
                continue
            return answer  # type: ignore[no-any-return]

    def _expect(self, what: str, limit_s: float) -> None:
        if not self.conn.poll(limit_s):
            self.stop()
            raise InfrastructureError(f"the trial process did not get {what} in {limit_s:g} s")
        got = self.conn.recv()
        if got != what:
            raise InfrastructureError(f"the trial process said {got!r}, not {what!r}")

    def died(self) -> Exception:
        """The error of a server that ended: lost (killed from outside) or failed."""
        try:
            code = self.proc.wait(5.0)
        except subprocess.TimeoutExpired:
            code = None
        self.stop()
        if code is not None and code < 0 and -code in LOST_SIGNALS:
            name = signal.Signals(-code).name
            return InfrastructureError(f"trial process killed by {name} (out of memory?)")
        return OdometryError(f"trial process died (exit code {code})")

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        """Kill the process (if still running) and wait for it."""
        self.conn.close()
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
