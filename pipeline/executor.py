"""Worker processes for independent jobs: ``open_executor`` (a process pool or Dask) and
``map_in_processes`` (every job of a list, ``workers`` at a time, results in list order).

Pool workers are spawned (no forked state) and end when this process ends, for any reason
(``pipeline/lifetime.py``; docs/design.md, "Processes").
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from typing import Any, TypeVar

from pipeline.errors import ConfigError

R = TypeVar("R")
THREADS_ENV = "ADAPTUNE_THREADS"
"""The environment variable that caps the threads of one process's own parallel work
(``process_threads``)."""


def process_threads() -> int:
    """Threads this process's own parallel work may use (a simulated scan's ray casting and
    kernels): ``ADAPTUNE_THREADS`` where set (in a pool worker of ``open_executor``: its share
    of the CPUs), else every CPU this process may run on."""
    value = _count_from_env(THREADS_ENV)
    if value is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
            os.cpu_count() or 1)
    return value


def _count_from_env(name: str, unit: str = "") -> int | None:
    """The integer >= 1 the environment variable ``name`` holds, None where it is unset or
    empty; ConfigError naming it otherwise (``unit``: what it counts, for the message)."""
    value = os.environ.get(name, "")
    if not value:
        return None
    if not value.isdigit() or int(value) < 1:
        raise ConfigError(f"{name} must be an integer >= 1{unit}, got {value!r}")
    return int(value)


MEMORY_ENV = "ADAPTUNE_WORKER_MEMORY"
"""The environment variable that gives one worker process the bytes of memory it may use
(``worker_memory_bytes``): set in every worker of ``open_executor`` to its share of the machine's,
and inherited by the processes it starts (trial servers)."""


def machine_memory_bytes() -> int | None:
    """Physical memory of this machine [bytes], None where it cannot be read."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def worker_memory_bytes() -> int | None:
    """Bytes of memory this process may use: ``ADAPTUNE_WORKER_MEMORY`` where set (a worker of
    ``open_executor``: the machine's memory divided among the workers, which all run at once),
    else the machine's; None where neither can be read."""
    value = _count_from_env(MEMORY_ENV, " (bytes)")
    return machine_memory_bytes() if value is None else value


def _memory_share(workers: int) -> str:
    """``MEMORY_ENV``'s value for one of ``workers`` processes started here: this process's
    memory divided among them ("" where it is unknown: each reads the machine's)."""
    memory = worker_memory_bytes()
    return str(max(1, memory // workers)) if memory else ""


def _start_worker(parent_pid: int, threads: int, memory: str = "") -> None:
    """Initializer of a pool worker: ends with its parent, leaves Ctrl-C to it
    (``pipeline.lifetime.become_pool_worker``) and uses ``threads`` threads of its own."""
    from pipeline.lifetime import become_pool_worker

    become_pool_worker(parent_pid)
    os.environ[THREADS_ENV] = str(threads)
    if memory:
        os.environ[MEMORY_ENV] = memory


@contextlib.contextmanager
def open_executor(workers: int, dask: str | None = None,
                  share: int | None = None) -> Iterator[Executor]:
    """A concurrent.futures Executor with ``workers`` processes, shut down on exit.

    ``dask=None``: ProcessPoolExecutor (spawn context; its workers end with this process and
    share this process's threads: ``process_threads() // share`` each, at least 1, and its
    memory: ``worker_memory_bytes() // share`` each, which sizes their scan caches; ``share``
    is the number of processes started here that run at once, default ``workers``: more when
    several pools run side by side).
    ``"local"``: a Dask LocalCluster (``workers`` processes, one thread each, the memory shared
    the same way). An address: a
    client of that scheduler, whose workers may be started the plain way (``dask worker
    tcp://...``): trial servers are started with subprocess, which daemonic processes may do.
    """
    if dask is None:
        share = workers if share is None else share
        pool = ProcessPoolExecutor(max_workers=workers,
                                   mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_start_worker,
                                   initargs=(os.getpid(), max(1, process_threads() // share),
                                             _memory_share(share)))
        try:
            yield pool
        except BaseException:  # Ctrl-C, SIGTERM, an error: do not wait for running trials
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.kill()  # their trial servers and tools end with them
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        return
    with _dask_client(workers, dask) as client:
        # pure=False: a trial run again (lost) is a new task, never the stored result
        yield client.get_executor(pure=False)


@contextlib.contextmanager
def _dask_client(workers: int, address: str) -> Iterator[Any]:
    """A client of a new LocalCluster (``"local"``) or of the scheduler at ``address``."""
    from distributed import Client, LocalCluster

    if address == "local":
        share = _memory_share(workers)
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, env={MEMORY_ENV: share} if share else {})
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()
        return
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"cannot reach the Dask scheduler at {address} ({exc})") from None
    try:
        yield client
    finally:
        client.close()


def map_in_processes(fn: Callable[..., R], jobs: Sequence[tuple[Any, ...]], workers: int,
                     on_done: Callable[[int, R], object] | None = None,
                     order: Sequence[int] | None = None) -> list[R]:
    """``[fn(*job) for job in jobs]``, ``workers`` jobs at a time in spawned processes (in this
    process when ``workers`` is 1 or there is one job). ``on_done(i, result)`` runs here as job
    i finishes; ``order``: the order the jobs are started in (longest first keeps the workers
    busy to the end), default the list's. ``fn`` and the jobs must be picklable; the first
    failure ends the other jobs and is raised."""
    order = list(range(len(jobs))) if order is None else list(order)
    results: dict[int, R] = {}
    if workers == 1 or len(jobs) <= 1:
        for i in order:
            results[i] = fn(*jobs[i])
            if on_done is not None:
                on_done(i, results[i])
    else:
        with open_executor(min(workers, len(jobs))) as pool:
            futures = {pool.submit(fn, *jobs[i]): i for i in order}
            for fut in as_completed(futures):
                i = futures[fut]
                results[i] = fut.result()
                if on_done is not None:
                    on_done(i, results[i])
    return [results[i] for i in range(len(jobs))]


def costliest_first(costs: Sequence[float]) -> list[int]:
    """Indices of ``costs`` (one a job) by falling cost, ties in list order: the order to start
    jobs in on a pool, so that no worker is left with a long one at the end (a world's rays:
    an HDL-64E world costs about twice an HDL-32E one of as many frames)."""
    return sorted(range(len(costs)), key=lambda i: -costs[i])
