"""Child processes that end when their parent ends, for any reason (docs/design.md, "Processes").

The tools every process adaptune starts relies on:
- ``die_with_parent(parent_pid)``: called first thing in a child; on Linux the kernel sends the
  child SIGKILL when the thread that started it ends (``prctl(PR_SET_PDEATHSIG)``), which also
  covers a SIGKILLed parent. Elsewhere (no prctl) a thread watches the parent's pid instead.
- ``exit_on_hangup(fd)``: a daemon thread that ends the process when the other end of ``fd``
  (a pipe or socket whose writer is the parent) closes: the parent is gone.
- the *guard* (``python -I lifetime.py LIFELINE WORKDIR -- ARGV...``): runs an external
  tool in a session of its own and outlives its parent on purpose, just long enough to clean
  up: when the lifeline (a pipe whose write end only the parent holds) closes, because the
  parent cancelled the run or died (even by SIGKILL), it kills the tool's whole process group
  and removes WORKDIR (unless it is ""). The tool itself dies with the guard
  (PR_SET_PDEATHSIG). When the tool ends by itself the guard kills what the tool left running
  in its group and ends the same way (same exit status, or the same signal).
- ``become_pool_worker`` (a process pool's initializer) and ``exit_on_termination`` (SIGTERM
  and SIGHUP of the main process unwind like Ctrl-C, so its context managers end the pool).

This module imports the standard library only, so that the guard starts in ~0.1 s.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from typing import Any

GUARD_CANNOT_RUN = 127
"""The guard's exit status when the tool cannot be started (stderr says why)."""

PR_SET_PDEATHSIG = 1
"""linux/prctl.h: the signal a process gets when its parent (thread) dies."""


def _libc_prctl() -> Any:
    """libc's ``prctl`` (the C library this interpreter is linked with), None off Linux."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _libc_prctl()


def set_parent_death_signal(sig: int = signal.SIGKILL) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent (the thread that started
    it) ends; False where the platform has no ``prctl`` (then use ``watch_parent_pid``).
    Safe between fork and exec (``preexec_fn``): one system call."""
    if _PRCTL is None:
        return False
    return bool(_PRCTL(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0)


def die_with_parent(parent_pid: int) -> None:
    """Make this process end when ``parent_pid`` (its parent) ends; ends at once if it already
    has (the parent died before this call)."""
    if not set_parent_death_signal():
        watch_parent_pid(parent_pid)
    if os.getppid() != parent_pid:
        os._exit(1)


def become_pool_worker(parent_pid: int) -> None:
    """Initializer of a process-pool worker: it ends with its parent (``parent_pid``) and
    ignores Ctrl-C, which the parent handles (by ending its workers)."""
    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def exit_on_termination() -> None:
    """In the main process: SIGTERM and SIGHUP raise SystemExit(128 + signal) in the main
    thread, so that ``finally`` blocks and context managers end children and remove
    temporary files (Python's default is to die on the spot)."""

    def terminate(signum: int, frame: object) -> None:
        raise SystemExit(128 + signum)

    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers belong to the main thread (e.g. a CLI test runner's thread)
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, terminate)


def watch_parent_pid(parent_pid: int, period_s: float = 0.5) -> None:
    """A daemon thread that ends the process once its parent is no longer ``parent_pid``."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(period_s)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def wait_hangup(fd: int, timeout_s: float | None = None) -> bool:
    """Block until the peer of ``fd`` closes (POLLHUP / POLLERR); False on timeout. Data that
    arrives is not read and does not wake it up."""
    poller = select.poll()
    poller.register(fd, 0)  # no events asked: only hang-up and error are reported
    timeout_ms = None if timeout_s is None else max(0, int(timeout_s * 1000))
    return bool(poller.poll(timeout_ms))


def exit_on_hangup(fd: int) -> None:
    """A daemon thread that ends this process (and its process group, when it leads one) as
    soon as the peer of ``fd`` closes."""

    def watch() -> None:
        wait_hangup(fd)
        if os.getpgid(0) == os.getpid():
            with contextlib.suppress(OSError):
                os.killpg(0, signal.SIGKILL)
        os._exit(1)

    threading.Thread(target=watch, name="hangup-watch", daemon=True).start()


def kill_group(pgid: int) -> None:
    """SIGKILL the process group ``pgid`` (nothing when it is gone)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


# -- the guard -----------------------------------------------------------------------------

def guard_argv(lifeline_fd: int, workdir: str, argv: list[str]) -> list[str]:
    """The command line that runs ``argv`` under the guard (see the module docstring): this
    file run as a script in isolated mode (standard library only, whatever the cwd)."""
    return [sys.executable, "-I", os.path.abspath(__file__), str(lifeline_fd), workdir, "--",
            *argv]


def _guard(lifeline_fd: int, workdir: str, argv: list[str]) -> int:
    """Run ``argv``; its exit status, or a negative signal number. Cleans up on hang-up."""
    try:
        tool = subprocess.Popen(argv, start_new_session=True, stdin=subprocess.DEVNULL,
                                preexec_fn=set_parent_death_signal)  # single-threaded here
    except OSError as exc:
        print(f"adaptune guard: cannot run {argv[0]!r} ({exc.strerror})", file=sys.stderr)
        return GUARD_CANNOT_RUN
    try:
        poller = select.poll()
        poller.register(lifeline_fd, 0)  # hang-up only
        pidfd = _pidfd(tool.pid)
        if pidfd is not None:
            poller.register(pidfd, select.POLLIN)  # readable once the tool has ended
        while True:
            events = dict(poller.poll(None if pidfd is not None else 50))
            if lifeline_fd in events:  # the parent cancelled or died: clean up
                kill_group(tool.pid)
                tool.wait()
                if workdir:
                    shutil.rmtree(workdir, ignore_errors=True)
                return 1
            code = tool.poll()
            if code is not None:
                return code
    finally:
        kill_group(tool.pid)  # whatever the tool left running in its group


def _pidfd(pid: int) -> int | None:
    """A file descriptor that becomes readable when ``pid`` ends (Linux >= 5.3), else None."""
    try:
        return os.pidfd_open(pid)
    except (AttributeError, OSError):
        return None


def main(argv: list[str]) -> int:
    """``python -I lifetime.py LIFELINE_FD WORKDIR -- ARGV...``."""
    if len(argv) < 4 or argv[2] != "--":
        print("usage: python -I lifetime.py LIFELINE_FD WORKDIR -- ARGV...", file=sys.stderr)
        return 2
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the parent decides, through the lifeline
    code = _guard(int(argv[0]), argv[1], argv[3:])
    if code < 0:  # end the way the tool ended, so that the parent sees the same status
        signal.signal(-code, signal.SIG_DFL)
        os.kill(os.getpid(), -code)
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
