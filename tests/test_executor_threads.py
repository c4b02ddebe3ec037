"""A process's own threads (``pipeline.executor.process_threads``): every CPU by default,
ADAPTUNE_THREADS where set, a share of the CPUs in each pool worker (no oversubscription when
the pipeline runs several simulations at once)."""

from __future__ import annotations

import os

import pytest

from pipeline.errors import ConfigError
from pipeline.executor import THREADS_ENV, map_in_processes, process_threads


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
