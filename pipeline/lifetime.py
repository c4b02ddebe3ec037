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
  in its group and ends the same way (same exit status, or the same signal). The guard tells
  its parent the tool's pid (first line of its stdout) and, when it ends by itself, the
  tool's status (second line); ``run_guarded`` is the parent's side: it watches the guard, and
  when the guard dies without that last line (killed from outside, even by SIGKILL) it kills
  the tool's process group itself, so nothing the tool started outlives the run.
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
from dataclasses import dataclass
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


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP in the main process: unwinds as Ctrl-C's KeyboardInterrupt does;
    ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def exit_on_termination() -> None:
    """In the main process: SIGTERM and SIGHUP raise Terminated (a KeyboardInterrupt) in the
    main thread, so that ``finally`` blocks and context managers end children and remove
    temporary files (Python's default is to die on the spot), as Ctrl-C does."""

    def terminate(signum: int, frame: object) -> None:
        raise Terminated(signum)

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


@dataclass(frozen=True)
class GuardedRun:
    """How a tool run under the guard ended: ``status`` (its exit status, or minus the signal
    that ended it; GUARD_CANNOT_RUN when it could not start), its ``stderr``, and
    ``guard_signal``: the signal that killed the guard itself from outside (0 when the guard
    ended by itself); the tool's group was then killed by ``run_guarded``."""

    status: int
    stderr: bytes
    guard_signal: int = 0


DRAIN_S = 1.0
"""How long the parent still reads the tool's stderr once the guard has ended [s] (a
process that left the tool's group may hold it open)."""
CANCEL_WAIT_S = 10.0
"""How long a cancelled guard gets to kill the tool and remove its work folder [s]."""


def run_guarded(argv: list[str], cwd: str | None, time_limit_s: float | None,
                workdir: str = "") -> GuardedRun:
    """Run ``argv`` under the guard (module docstring) and wait for it; the parent's side.

    Past ``time_limit_s`` (and on any exception here, Ctrl-C or SIGTERM included) the run is
    cancelled: the lifeline closes, the guard kills the tool's group and removes ``workdir``;
    TimeoutError is raised past the limit, the exception otherwise. When the guard itself is
    killed from outside, the tool's group is killed here. OSError when the guard cannot start.
    """
    lifeline, keep = os.pipe()  # the guard cleans up when `keep` closes
    try:
        proc = subprocess.Popen(guard_argv(lifeline, workdir, argv), cwd=cwd,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                stdin=subprocess.DEVNULL, pass_fds=(lifeline,),
                                start_new_session=True)
    except BaseException:
        os.close(keep)
        raise
    finally:
        os.close(lifeline)
    assert proc.stdout is not None and proc.stderr is not None
    tool_pid = 0
    with proc:
        try:
            tool_pid = _reported(proc.stdout.readline(), "pid")
            deadline = None if time_limit_s is None else time.monotonic() + time_limit_s
            err = _stderr_until_exit(proc, deadline)
        except BaseException:
            _cancel(proc, keep, tool_pid)
            raise
        if err is None:
            _cancel(proc, keep, tool_pid)
            raise TimeoutError(f"{argv[0]} outlived its time limit of {time_limit_s:g} s")
        os.close(keep)
        status = _reported(proc.stdout.read(), "status", None)
        if status is None and proc.returncode < 0:  # the guard was killed, silently
            if tool_pid:
                kill_group(tool_pid)
            return GuardedRun(proc.returncode, err + _drain(proc.stderr), -proc.returncode)
        return GuardedRun(proc.returncode if status is None else status,
                          err + _drain(proc.stderr))


def _reported(data: bytes, key: str, default: int | None = 0) -> Any:
    """The number after ``key`` in the guard's report lines, else ``default``."""
    for line in data.decode(errors="replace").splitlines():
        name, _, value = line.partition(" ")
        if name == key and value.lstrip("-").isdigit():
            return int(value)
    return default


def _stderr_until_exit(proc: subprocess.Popen[bytes], deadline: float | None) -> bytes | None:
    """The guard's stderr until the guard ends (None when ``deadline`` passes first)."""
    assert proc.stderr is not None
    err_fd = proc.stderr.fileno()
    chunks: list[bytes] = []
    poller = select.poll()
    poller.register(err_fd, select.POLLIN)
    pidfd = _pidfd(proc.pid)
    if pidfd is not None:
        poller.register(pidfd, select.POLLIN)  # readable once the guard has ended
    try:
        while proc.poll() is None:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return None
            wait_ms = 50 if pidfd is None else None if left is None else left * 1000
            for fd, _ in poller.poll(wait_ms if wait_ms is None else max(1, int(wait_ms))):
                if fd == err_fd:
                    data = os.read(err_fd, 65536)
                    chunks.append(data)
                    if not data:  # EOF: nothing more to read, wait for the end alone
                        poller.unregister(err_fd)
    finally:
        if pidfd is not None:
            os.close(pidfd)
    return b"".join(chunks)


def _drain(stream: Any, timeout_s: float = DRAIN_S) -> bytes:
    """What is left to read in ``stream``, waiting at most ``timeout_s`` for its end."""
    fd = stream.fileno()
    chunks: list[bytes] = []
    deadline = time.monotonic() + timeout_s
    while (left := deadline - time.monotonic()) > 0 and select.select([fd], [], [], left)[0]:
        data = os.read(fd, 65536)
        if not data:
            break
        chunks.append(data)
    return b"".join(chunks)


def _cancel(proc: subprocess.Popen[bytes], keep: int, tool_pid: int) -> None:
    """Close the lifeline (the guard kills the tool's group and removes the work folder) and
    wait for the guard; SIGKILL it, and the tool's group, when it does not end in time."""
    os.close(keep)
    try:
        proc.wait(timeout=CANCEL_WAIT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    if proc.returncode < 0 and tool_pid:  # killed: clean up after it
        kill_group(tool_pid)


def _guard(lifeline_fd: int, workdir: str, argv: list[str]) -> int:
    """Run ``argv``; its exit status, or a negative signal number. Cleans up on hang-up."""
    try:  # the tool's stdout is not read (this stdout is the parent's report channel)
        tool = subprocess.Popen(argv, start_new_session=True, stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL,
                                preexec_fn=set_parent_death_signal)  # single-threaded here
    except OSError as exc:
        # the guard process: stderr is its only voice
        print(f"adaptune guard: cannot run {argv[0]!r} ({exc.strerror})",  # noqa: T201
              file=sys.stderr)
        return GUARD_CANNOT_RUN
    _report(f"pid {tool.pid}")  # the group the parent kills should this guard die
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


def _report(line: str) -> None:
    """One line to the parent (the guard's stdout); nothing when the parent is gone."""
    with contextlib.suppress(OSError):
        os.write(1, f"{line}\n".encode())


def main(argv: list[str]) -> int:
    """``python -I lifetime.py LIFELINE_FD WORKDIR -- ARGV...``."""
    if len(argv) < 4 or argv[2] != "--":
        print("usage: python -I lifetime.py LIFELINE_FD WORKDIR -- ARGV...",  # noqa: T201
              file=sys.stderr)
        return 2
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the parent decides, through the lifeline
    code = _guard(int(argv[0]), argv[1], argv[3:])
    _report(f"status {code}")  # ended by itself (a guard killed from outside says nothing)
    if code < 0:  # end the way the tool ended, so that the parent sees the same status
        signal.signal(-code, signal.SIG_DFL)
        os.kill(os.getpid(), -code)
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
