"""A ROS 1 graph for one test: a real ``roscore`` on a free port of its own, and every process a
test starts beside it, each run under adaptune's guard (``pipeline/lifetime.py``) so that it
and all it starts end with the test, even when pytest itself is killed: closing a guard's
lifeline kills the tool's whole process group. roscore starts rosmaster and rosout in sessions
of their own (roslaunch's ``setsid``), out of its group: a *reaper* (``REAPER``, holding a
lifeline too) kills their groups when the test ends, however it ends.

The master is asked through its XML-RPC API with the standard library (``getSystemState``,
``lookupNode``, a node's ``getBusInfo``), so the test process imports no rospy.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import pytest

from pipeline.lifetime import guard_argv, kill_group

WAIT_S = 300.0
"""A hang guard only: how long a wait for the graph may take before the test fails."""
POLL_S = 0.1
CALLER = "/adaptune_test"


REAPER = """
import os, select, signal, sys
poll = select.poll()
poll.register(int(sys.argv[1]), 0)
poll.poll()
for pid in sys.argv[2:]:
    try:
        os.killpg(int(pid), signal.SIGKILL)
    except OSError:
        pass
"""
"""Run as ``python -I -c REAPER LIFELINE PID...``: when the lifeline closes, SIGKILL the process
groups of the PIDs (session leaders)."""


def require_ros() -> None:
    """Skip when ROS 1 is not installed for this interpreter (roscore, rosbag, rospy); with
    CI=true fail instead: `make setup` installs it (.ci/install-system-deps, .ci/ros-python)."""
    import importlib.util

    missing = [t for t in ("roscore", "rosbag") if shutil.which(t) is None]
    missing += [m for m in ("rospy", "dynamic_reconfigure") if importlib.util.find_spec(m) is None]
    if missing:
        msg = f"ROS 1 not installed for this venv (missing {', '.join(missing)}; make setup)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Guarded:
    """A process run under the guard: ``pid`` the tool's, ``log`` its stderr."""

    name: str
    guard: subprocess.Popen[bytes]
    lifeline: int
    pid: int
    log: Path
    ended: bool = False

    def status(self, timeout_s: float = WAIT_S) -> int:
        """Wait for the tool to end by itself: its exit status (minus the signal)."""
        out, _ = self.guard.communicate(timeout=timeout_s)
        self.ended = True
        for line in out.decode().splitlines():
            if line.startswith("status "):
                return int(line.split()[1])
        raise AssertionError(f"{self.name}: the guard ended without a status\n{self.text()}")

    def interrupt(self, sig: int = signal.SIGINT) -> int:
        """Send the tool ``sig``; its exit status."""
        os.kill(self.pid, sig)
        return self.status()

    def text(self) -> str:
        return self.log.read_text(errors="replace")

    def end(self) -> None:
        """Close the lifeline: the guard kills the tool's group; wait for it."""
        if self.lifeline >= 0:
            os.close(self.lifeline)
            self.lifeline = -1
        try:
            self.guard.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.guard.kill()
            self.guard.wait()
        kill_group(self.pid)


class RosGraph:
    """``with RosGraph(folder) as graph``: roscore on a free port; ``start`` more processes in
    its environment; on exit every one of them ends (their groups killed) and none is left."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.port = free_port()
        self.uri = f"http://127.0.0.1:{self.port}"
        self.env = {**os.environ, "ROS_MASTER_URI": self.uri, "ROS_IP": "127.0.0.1",
                    "ROS_HOME": str(folder / "ros_home"), "PYTHONUNBUFFERED": "1"}
        self.env.pop("ROS_HOSTNAME", None)
        self.processes: list[Guarded] = []

    def __enter__(self) -> RosGraph:
        self.core = self.start("roscore", ["roscore", "-p", str(self.port)])
        self.wait_until(lambda: self._pid("/rosout") is not None, "roscore runs /rosout")
        self.core_pids = [self._master_pid(), self._pid("/rosout")]
        lifeline, self._reaper_keep = os.pipe()
        self._reaper = subprocess.Popen(
            [sys.executable, "-I", "-c", REAPER, str(lifeline), *map(str, self.core_pids)],
            pass_fds=(lifeline,), start_new_session=True, stdin=subprocess.DEVNULL)
        os.close(lifeline)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        for proc in reversed(self.processes):
            proc.end()
        os.close(self._reaper_keep)
        self._reaper.wait(timeout=30)
        groups = {p.name: p.pid for p in self.processes}
        groups.update(zip(("rosmaster", "rosout"), self.core_pids, strict=True))
        left = [name for name, pgid in groups.items() if _group_alive(pgid)]
        assert not left, f"processes left running: {left}"

    @property
    def master(self) -> Any:
        return xmlrpc.client.ServerProxy(self.uri)

    def _master_pid(self) -> int:
        return int(self.master.getPid(CALLER)[2])

    def _pid(self, node: str) -> int | None:
        """The pid of ``node`` (None while the master or the node does not answer)."""
        try:
            code, _, uri = self.master.lookupNode(CALLER, node)
            if code != 1:
                return None
            code, _, pid = xmlrpc.client.ServerProxy(uri).getPid(CALLER)
        except OSError:
            return None
        return int(pid) if code == 1 else None

    def start(self, name: str, argv: list[str]) -> Guarded:
        """Run ``argv`` under the guard in the graph's environment; stderr to a log file."""
        log = self.folder / f"{name}.log"
        lifeline, keep = os.pipe()
        with log.open("wb") as err:
            guard = subprocess.Popen(guard_argv(lifeline, "", argv), env=self.env,
                                     stdout=subprocess.PIPE, stderr=err,
                                     stdin=subprocess.DEVNULL, pass_fds=(lifeline,),
                                     start_new_session=True, cwd=self.folder)
        os.close(lifeline)
        assert guard.stdout is not None
        first = guard.stdout.readline().decode()
        if not first.startswith("pid "):
            os.close(keep)
            raise AssertionError(f"{name} did not start: {first!r}\n{log.read_text()}")
        proc = Guarded(name, guard, keep, int(first.split()[1]), log)
        self.processes.append(proc)
        return proc

    def wait_until(self, condition: Callable[[], bool], what: str) -> None:
        """Poll ``condition`` until it holds (a hang guard of WAIT_S fails the test)."""
        deadline = time.monotonic() + WAIT_S
        while not condition():
            dead = [p for p in self.processes if not p.ended and p.guard.poll() is not None]
            if dead:
                raise AssertionError(f"waiting until {what}: {dead[0].name} ended\n"
                                     f"{dead[0].text()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"waited {WAIT_S:g} s until {what}")
            time.sleep(POLL_S)

    def subscribers(self, topic: str) -> set[str]:
        """The nodes registered as subscribers of ``topic``."""
        _, _, (_, subscribers, _) = self.master.getSystemState(CALLER)
        return next((set(nodes) for t, nodes in subscribers if t == topic), set())

    def services(self) -> set[str]:
        _, _, (_, _, services) = self.master.getSystemState(CALLER)
        return {s for s, _ in services}

    def shutdown(self, node: str) -> None:
        """Ask ``node`` to shut down through its XML-RPC API, as ``rosnode kill`` does."""
        code, msg, uri = self.master.lookupNode(CALLER, node)
        assert code == 1, msg
        # the node's XML-RPC server may close before it answers (the call is retried on a
        # closed connection, then refused): whether the node ended is the caller's to check
        with contextlib.suppress(OSError):
            xmlrpc.client.ServerProxy(uri).shutdown(CALLER, "the test ends it")

    def connected(self, node: str, topic: str) -> bool:
        """True when ``node`` has a live inbound connection on ``topic`` (its bus info)."""
        code, _, uri = self.master.lookupNode(CALLER, node)
        if code != 1:
            return False
        _, _, bus = xmlrpc.client.ServerProxy(uri).getBusInfo(CALLER)
        return any(c[4] == topic and c[2] == "i" and c[5] for c in bus)


def _group_alive(pgid: int) -> bool:
    """True while a process of group ``pgid`` runs (zombies, ended but not yet reaped, do not
    count)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        if int(fields[2]) == pgid and fields[0] != "Z":
            return True
    return False
