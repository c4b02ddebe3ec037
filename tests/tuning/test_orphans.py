"""Every process adaptune starts ends when its parent ends, and a ``command`` tool's work
directory goes with it: the parent is really killed (SIGKILL, SIGTERM, SIGINT) and every
descendant seen before must be gone (or a zombie) within a few seconds.

The tool (tests/odometry/scripts/stubborn.py) never finishes and starts a grandchild in its
process group; it records its pid, the grandchild's and its work directory when running.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from pipeline.tuning.job import TrialJob
from pipeline.tuning.worker import WorkerState

STUBBORN = Path(__file__).parents[1] / "odometry" / "scripts" / "stubborn.py"
SPACE = [{"name": "bias", "low": 0.0, "high": 1.0, "default": 0.5}]


def command_options(record_dir: Path, work_root: Path) -> dict[str, object]:
    return {"command": ["{python}", str(STUBBORN), "{workdir}", str(record_dir)],
            "space": SPACE, "workdir": str(work_root)}


def gone(pid: int) -> bool:
    """True when ``pid`` no longer runs (no such process, or a zombie nobody reaped)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return True
    return state in ("Z", "X")


def descendants(root: int) -> set[int]:
    """Pids of every process below ``root`` now (from /proc: parent links)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (FileNotFoundError, ProcessLookupError, IndexError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    out: set[int] = set()
    todo = [root]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def wait_for(predicate: object, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def running_tool(record_dir: Path, main: subprocess.Popen[bytes] | None = None,
                 timeout_s: float = 60.0) -> dict[str, object]:
    """The record of the running tool (waits for it; fails at once if ``main`` ended)."""

    def started() -> bool:
        if main is not None and main.poll() is not None:
            raise AssertionError(f"adaptune ended first: {main.stderr.read()!r}")  # type: ignore[union-attr]
        return any(record_dir.glob("*.json"))

    wait_for(started, timeout_s, "the tool to start")
    (record,) = record_dir.glob("*.json")
    return json.loads(record.read_text())  # type: ignore[no-any-return]


def assert_all_gone(pids: set[int], work_root: Path) -> None:
    wait_for(lambda: all(gone(p) for p in pids), 10.0,
             f"processes {sorted(p for p in pids if not gone(p))} to end")
    wait_for(lambda: not any(work_root.iterdir()), 10.0, f"{work_root} to be emptied")


@pytest.fixture
def dirs(tmp_path: Path) -> Iterator[tuple[Path, Path]]:
    record_dir, work_root = tmp_path / "records", tmp_path / "work"
    record_dir.mkdir()
    work_root.mkdir()
    yield record_dir, work_root
    for record in record_dir.glob("*.json"):  # never leave a tool behind, even on failure
        r = json.loads(record.read_text())
        for pid in (r["pid"], r["child"]):
            if not gone(pid):
                os.kill(pid, signal.SIGKILL)


def cli(*args: str) -> subprocess.Popen[bytes]:
    """``adaptune ARGS`` with Ctrl-C as a user's shell gives it (default action, unblocked),
    whatever the test process inherited or set (a background job ignores SIGINT)."""
    return subprocess.Popen([sys.executable, "-m", "stages.cli", *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=_default_ctrl_c)


def run_command(sequence: Path, dirs: tuple[Path, Path], out: Path) -> subprocess.Popen[bytes]:
    """``adaptune run -a command`` with the stubborn tool over ``sequence``."""
    record_dir, work_root = dirs
    opts = command_options(record_dir, work_root)
    return cli("run", "-a", "command", "-o", f"command={json.dumps(opts['command'])}",
               "-o", f"space={json.dumps(SPACE)}", "-o", f"workdir={work_root}",
               str(sequence), "--out", str(out))


def _default_ctrl_c() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killing_adaptune_trials_ends_every_process_it_started(
        sequences: list[Path], tmp_path: Path, dirs: tuple[Path, Path], sig: int) -> None:
    """Pool worker, resource tracker, trial server, guard, tool and the tool's child."""
    record_dir, work_root = dirs
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({"base": {"seed": 1, "length_m": 5.0}, "trials": {
        "algorithm": "command", "iterations": 2, "workers": 1, "time_limit_s": 120.0,
        "adapter_options": command_options(record_dir, work_root)}}))
    main = cli("trials", str(sequences[0]), "--out", str(tmp_path / "out"), "--params",
               str(params))
    try:
        tool = running_tool(record_dir, main)
        below = descendants(main.pid)
        assert {tool["pid"], tool["child"]} <= below and len(below) >= 5
        os.kill(main.pid, sig)
        main.wait(30)
        assert_all_gone(below, work_root)
    finally:
        if main.poll() is None:
            main.kill()
            main.wait()


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_killing_adaptune_run_ends_the_tool_and_removes_its_work_directory(
        sequences: list[Path], dirs: tuple[Path, Path], tmp_path: Path, sig: int) -> None:
    record_dir, work_root = dirs
    main = run_command(sequences[0], dirs, tmp_path / "t.parquet")
    try:
        tool = running_tool(record_dir, main)
        below = descendants(main.pid)
        assert {tool["pid"], tool["child"]} <= below
        os.kill(main.pid, sig)
        code = main.wait(30)
        assert_all_gone(below, work_root)
        if sig != signal.SIGKILL:  # ended through its own clean-up, in one line, exit 130
            lines = main.stderr.read().decode().strip().splitlines()  # type: ignore[union-attr]
            assert code == 130, (code, lines)
            assert lines == [f"adaptune: interrupted ({signal.Signals(sig).name})"], lines
    finally:
        if main.poll() is None:
            main.kill()
            main.wait()


def parent_of(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def test_a_killed_guard_takes_the_tools_group_along_and_run_ends(
        sequences: list[Path], dirs: tuple[Path, Path], tmp_path: Path) -> None:
    """The guard itself SIGKILLed (issue 32, case 1): the tool died with it but its child was
    re-parented to init, the work folder stayed and `adaptune run` waited forever for the
    child's end of the stderr pipe, deaf to SIGTERM. Now the parent watches the guard, kills
    the tool's group itself and ends in one line."""
    record_dir, work_root = dirs
    main = run_command(sequences[0], dirs, tmp_path / "t.parquet")
    try:
        tool = running_tool(record_dir, main)
        below = descendants(main.pid)
        os.kill(parent_of(int(tool["pid"])), signal.SIGKILL)  # the guard
        code = main.wait(30)
        assert_all_gone(below, work_root)
        lines = main.stderr.read().decode().strip().splitlines()  # type: ignore[union-attr]
        assert code == 1 and len(lines) == 1, lines
        assert "guard" in lines[0] and "SIGKILL" in lines[0], lines
        assert not (tmp_path / "t.parquet").exists()
    finally:
        if main.poll() is None:
            main.kill()
            main.wait()


def test_a_trial_process_killed_at_its_hard_limit_takes_the_tool_along(
        sequences: list[Path], dirs: tuple[Path, Path], tmp_path: Path) -> None:
    """The tuner SIGKILLs a trial server that outlives its limit (or the OOM killer does)."""
    record_dir, work_root = dirs
    job = TrialJob(adapter="command", algorithm="command", sequences=(("a", str(sequences[0])),),
                   trial=0, seed=0, params={"bias": 0.5}, out_dir=str(tmp_path / "out"),
                   length_m=5.0, penalty_pct=100.0, jump_limit_m=5.0, time_limit_s=120.0,
                   adapter_options=command_options(record_dir, work_root))
    state = WorkerState()
    results = []
    runner = threading.Thread(target=lambda: results.append(state.run(job)))
    runner.start()
    try:
        tool = running_tool(record_dir)
        server = parent_of(parent_of(int(tool["pid"])))  # the tool's guard's parent
        below = descendants(server)
        os.kill(server, signal.SIGKILL)
        runner.join(30)
        assert results[0].status == "lost" and "SIGKILL" in results[0].error
        assert_all_gone(below | {server}, work_root)
    finally:
        state.close()
