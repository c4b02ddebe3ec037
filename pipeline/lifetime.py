"""Child processes that end when their parent ends, for any reason (docs/design.md, "Processes").

Three tools, used by every process adaptune starts:
- ``die_with_parent(parent_pid)``: called first thing in a child; on Linux the kernel sends the
  child SIGKILL when the thread that started it ends (``prctl(PR_SET_PDEATHSIG)``), which also
  covers a SIGKILLed parent. Elsewhere (no prctl) a thread watches the parent's pid instead.
- ``exit_on_hangup(fd)``: a daemon thread that ends the process when the other end of ``fd``
  (a pipe or socket whose writer is the parent) closes: the parent is gone.
- the *guard* (``python -m pipeline.lifetime LIFELINE WORKDIR -- ARGV...``): runs an external
  tool in a session of its own and outlives its parent on purpose, just long enough to clean
  up: when the lifeline (a pipe whose write end only the parent holds) closes, because the
  parent cancelled the run or died (even by SIGKILL), it kills the tool's whole process group
  and removes WORKDIR. The tool itself dies with the guard (PR_SET_PDEATHSIG). When the tool
  ends by itself the guard kills what the tool left running in its group and ends the same way
  (same exit status, or the same signal).

This module imports the standard library only, so that the guard starts in ~0.1 s.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
"""linux/prctl.h: the signal a process gets when its parent (thread) dies."""


def _libc_prctl() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None
    return libc.prctl  # type: ignore[no-any-return]


def set_parent_death_signal(sig: int = signal.SIGKILL) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent dies; False where the
    platform has no ``prctl`` (then use ``watch_parent_pid``)."""
    prctl = _libc_prctl()
    if prctl is None:
        return False
    return bool(prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0)


def die_with_parent(parent_pid: int) -> None:
    """Make this process end when ``parent_pid`` (its parent) ends; ends at once if it already
    has (the parent died before this call)."""
    if not set_parent_death_signal():
        watch_parent_pid(parent_pid)
    if os.getppid() != parent_pid:
        os._exit(1)


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
    """The command line that runs ``argv`` under the guard (see the module docstring)."""
    return [sys.executable, "-m", "pipeline.lifetime", str(lifeline_fd), workdir, "--", *argv]


def _guard(lifeline_fd: int, workdir: str, argv: list[str]) -> int:
    """Run ``argv``; its exit status, or a negative signal number. Cleans up on hang-up."""
    try:
        tool = subprocess.Popen(argv, start_new_session=True, stdin=subprocess.DEVNULL,
                                preexec_fn=set_parent_death_signal)  # single-threaded here
    except OSError as exc:
        print(f"cannot run {argv[0]!r} ({exc.strerror})", file=sys.stderr)
        return 127
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
    """``python -m pipeline.lifetime LIFELINE_FD WORKDIR -- ARGV...``."""
    if len(argv) < 4 or argv[2] != "--":
        print("usage: python -m pipeline.lifetime LIFELINE_FD WORKDIR -- ARGV...", file=sys.stderr)
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
