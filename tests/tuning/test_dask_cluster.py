"""Trials on a real multi-process Dask cluster: ``dask scheduler`` and two plain (daemonic)
``dask worker`` processes over TCP on 127.0.0.1, one of them killed mid-study.

The processes are killed at the end whatever happens (the fixture), and every trial must be
in the table exactly once, scored as a run without the kill scores it.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from helpers.dask_cluster import stop, tcp_cluster
from helpers.tuning_settings import settings

from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import JOINT, trials_path


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """(scheduler address, [worker 1, worker 2]): plain workers, random free ports."""
    with tcp_cluster(tmp_path, 2) as (address, workers):
        yield address, workers


def table(out: Path, algorithm: str, study: str) -> dict[str, list]:
    d = pq.read_table(trials_path(out, algorithm, study)).to_pydict()
    return {k: v for k, v in d.items() if k != "wall_time_s"}


def test_a_study_on_a_tcp_cluster_survives_a_killed_worker(
        cluster: tuple[str, list[subprocess.Popen[bytes]]], sequences: list[Path],
        pool: Executor, tmp_path: Path) -> None:
    from distributed import Client

    address, workers = cluster
    s = settings(algorithm="helpers.tuning_adapters:sleepy", iterations=10, workers=2, dask=address)
    killed: list[str] = []
    watch = Client(address, timeout="20s")

    def kill_a_busy_worker(study: object, result: object) -> None:
        """After trial 2: kill the worker running a trial now (w1 if none is)."""
        if killed or result.trial < 2:  # type: ignore[attr-defined]
            return
        names = {a: w["name"] for a, w in watch.scheduler_info()["workers"].items()}
        deadline = time.monotonic() + 2.0
        busy: list[str] = []
        while not busy and time.monotonic() < deadline:
            busy = [names[a] for a, keys in watch.processing().items() if keys]
        name = busy[0] if busy else "w1"
        stop(workers[int(name[1]) - 1])
        killed.append(name)

    try:
        (summary,) = run_trials(sequences[:1], tmp_path / "dask", s, seed=4, progress=False,
                                on_trial=kill_a_busy_worker)
    finally:
        watch.close()
    assert killed and summary.lost == [] and summary.trials == 10
    got = table(tmp_path / "dask", "sleepy", "seq_a")
    assert got["trial"] == list(range(10)) and set(got["status"]) == {"ok"}
    # the same proposals and scores as on the local process pool: nothing lost or repeated
    run_trials(sequences[:1], tmp_path / "pool", s.model_copy(update={"dask": None}), seed=4,
               progress=False, executor=pool)
    assert got == table(tmp_path / "pool", "sleepy", "seq_a")
    # the joint study on the remaining worker
    (joint,) = run_trials(sequences, tmp_path / "fixed", s.model_copy(update={"iterations": 3}),
                          seed=4, joint=True, progress=False)
    assert joint.sequence == JOINT and joint.trials == 3 and joint.failed == 0
    assert table(tmp_path / "fixed", "sleepy", JOINT)["trial"] == [0, 1, 2]
