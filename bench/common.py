"""Shared pieces of the benchmark scripts: the Row type, timing, the table printer."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")
SMOKE_ENV = "ADAPTUNE_BENCH_SMOKE"
"""Set to 1 by the smoke test (tests/test_bench_smoke.py): every module on tiny inputs and
every timing once, to show that each figure is produced; no figure of a smoke run means
anything."""


def smoke() -> bool:
    """True in a smoke run (``SMOKE_ENV``)."""
    return os.environ.get(SMOKE_ENV) == "1"


def size(full: T, tiny: T) -> T:
    """``full`` (a count, a length, a grid), or ``tiny`` in a smoke run."""
    return tiny if smoke() else full


@dataclass
class Row:
    """One figure: our value beside the reference (same run, or the paper) and the target."""

    figure: str
    value: float
    unit: str
    reference: str = ""
    target: str = ""


def best_of(fn: Callable[[], object], repeat: int = 5, number: int = 1,
            clock: Callable[[], float] = time.perf_counter) -> float:
    """Best time [s] of ``number`` calls, over ``repeat`` rounds, divided by ``number`` (one
    call in a smoke run): wall time, or ``clock=time.process_time`` for the CPU time of the
    process (all its threads; what a single-threaded figure costs on an idle core, and far less
    noisy on a shared machine)."""
    if smoke():
        repeat = number = 1
    best = float("inf")
    for _ in range(repeat):
        t0 = clock()
        for _ in range(number):
            fn()
        best = min(best, (clock() - t0) / number)
    return best


def data_root() -> Path:
    """The real test data (ADAPTUNE_TEST_DATA, default ../shared/data)."""
    env = os.environ.get("ADAPTUNE_TEST_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


def format_table(rows: list[Row]) -> str:
    """A fixed-width text table of ``rows`` (pipeline.text_table, the CLI's renderer)."""
    import pyarrow as pa

    from pipeline.text_table import format_table as render

    head = ("figure", "value", "unit", "reference (same run / paper)", "target")
    body = [(r.figure, f"{r.value:.4g}", r.unit, r.reference, r.target) for r in rows]
    columns = list(zip(*body, strict=True)) if body else [()] * len(head)
    return render(pa.table({h: [str(c) for c in col] for h, col in zip(head, columns,
                                                                       strict=True)}),
                  footer=False)
