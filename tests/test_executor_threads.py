"""A process's own threads (``pipeline.executor.process_threads``): every CPU by default,
ADAPTUNE_THREADS where set, a share of the CPUs in each pool worker (no oversubscription when
the pipeline runs several simulations at once). Its memory the same way
(``worker_memory_bytes``): a pool worker sizes its scan cache from its share, so that the
caches of all the workers of a study fit in the machine at once."""

from __future__ import annotations

import os

import pytest

from pipeline.errors import ConfigError
from pipeline.executor import (
    MEMORY_ENV,
    THREADS_ENV,
    machine_memory_bytes,
    map_in_processes,
    open_executor,
    process_threads,
    worker_memory_bytes,
)
from pipeline.tuning.worker import SCAN_CACHE_MAX_BYTES, WorkerState, scan_cache_limit_bytes


def test_threads_default_to_the_cpus_and_follow_the_variable(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert process_threads() == len(os.sched_getaffinity(0))
    monkeypatch.setenv(THREADS_ENV, "3")
    assert process_threads() == 3
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(ConfigError, match=THREADS_ENV):
            process_threads()


def test_pool_workers_share_the_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "4")
    assert map_in_processes(process_threads, [(), ()], 2) == [2, 2]
    monkeypatch.setenv(THREADS_ENV, "1")
    assert map_in_processes(process_threads, [(), ()], 2) == [1, 1]


def test_memory_defaults_to_the_machine_and_follows_the_variable(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(MEMORY_ENV, raising=False)
    assert worker_memory_bytes() == machine_memory_bytes() > 0
    monkeypatch.setenv(MEMORY_ENV, "4000")
    assert worker_memory_bytes() == 4000
    for bad in ("0", "lots", "-1"):
        monkeypatch.setenv(MEMORY_ENV, bad)
        with pytest.raises(ConfigError, match=MEMORY_ENV):
            worker_memory_bytes()


def test_the_scan_cache_holds_half_a_workers_share_a_quarter_of_the_machine_at_most(
        monkeypatch: pytest.MonkeyPatch) -> None:
    assert scan_cache_limit_bytes(4000, 4000) == 1000  # one process: a quarter of the machine
    assert scan_cache_limit_bytes(2000, 4000) == 1000  # one of 2 workers: as many
    assert scan_cache_limit_bytes(250, 4000) == 125  # one of 16: half its share
    assert scan_cache_limit_bytes(1 << 40, 1 << 40) == SCAN_CACHE_MAX_BYTES == 8 << 30
    monkeypatch.setenv(MEMORY_ENV, "8000")
    assert scan_cache_limit_bytes() == WorkerState().scan_cache_limit_bytes == 4000


def test_pool_workers_share_the_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    # 16 workers of a 64 GB machine kept 8 GiB of scans each before: 128 GB
    monkeypatch.setenv(MEMORY_ENV, "8000")
    assert map_in_processes(worker_memory_bytes, [(), ()], 2) == [4000, 4000]
    assert map_in_processes(scan_cache_limit_bytes, [(), ()], 2) == [2000, 2000]


def test_a_local_dask_clusters_workers_share_the_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(MEMORY_ENV, "8000")
    with open_executor(2, "local") as pool:
        assert pool.submit(worker_memory_bytes).result() == 4000
        assert pool.submit(scan_cache_limit_bytes).result() == 2000
