"""A real Dask cluster for tests: ``dask scheduler`` and plain ``dask worker`` processes over
TCP on 127.0.0.1 (random free ports), each in a process group of its own that is SIGKILLed at
the end whatever happens."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

DASK = Path(sys.executable).with_name("dask")


def start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    """``dask ARGS`` with this interpreter's sys.path (test helper modules too)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.Popen([str(DASK), *args], stdout=subprocess.DEVNULL,
                            stderr=log.open("wb"), env=env, start_new_session=True)


def stop(proc: subprocess.Popen[bytes]) -> None:
    """SIGKILL the process group (the worker's nanny, its worker process, trial servers)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


@contextlib.contextmanager
def tcp_cluster(folder: Path, n_workers: int = 2
                ) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """(scheduler address, workers w1..wN): one thread each, logs and local folders in
    ``folder``."""
    info = folder / "scheduler.json"
    procs = [start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                    "--scheduler-file", str(info)], folder / "scheduler.log")]
    try:
        address = _scheduler_address(info, time.monotonic() + 30)
        assert address.startswith("tcp://127.0.0.1:")
        workers = [start(["worker", address, "--nworkers", "1", "--nthreads", "1",
                          "--no-dashboard", "--name", f"w{i}", "--local-directory",
                          str(folder / f"w{i}")], folder / f"w{i}.log")
                   for i in range(1, n_workers + 1)]
        procs += workers
        from distributed import Client

        with Client(address, timeout="20s") as client:
            client.wait_for_workers(n_workers, timeout=30)
        yield address, workers
    finally:
        for proc in procs:
            stop(proc)


def _scheduler_address(info: Path, deadline: float) -> str:
    """The address in the scheduler file ``info``, once the scheduler has written it whole (the
    file appears before its text: an empty or partial file is read again)."""
    while True:
        try:
            return str(json.loads(info.read_text())["address"])
        except (FileNotFoundError, json.JSONDecodeError, KeyError):
            assert time.monotonic() < deadline, f"{info}: no scheduler address in 30 s"
            time.sleep(0.1)
