"""Every benchmark module produces its figures (issue 32, case 8: `make bench` stopped at its
second module, ``evaluation``, and nothing ran it). Each module bench/run.py finds runs here on
tiny inputs with every timing done once (``ADAPTUNE_BENCH_SMOKE=1``, bench/common.py), in this
process; the test checks that it returns its rows, never what they measure."""

from __future__ import annotations

import math
from pathlib import Path
from types import ModuleType

import pytest
from helpers.scripts import load_script

BENCH = Path(__file__).resolve().parents[1] / "bench"
MODULES = sorted(p.stem.removeprefix("bench_") for p in BENCH.glob("bench_*.py"))


def bench_runner() -> ModuleType:
    """bench/run.py as a module (``run_module`` imports and runs one bench module)."""
    return load_script(BENCH / "run.py")


@pytest.mark.parametrize("name", MODULES)
def test_a_bench_module_produces_its_figures(name: str, monkeypatch: pytest.MonkeyPatch,
                                             test_data: Path) -> None:
    monkeypatch.setenv("ADAPTUNE_BENCH_SMOKE", "1")
    monkeypatch.setenv("ADAPTUNE_TEST_DATA", str(test_data))
    rows = bench_runner().run_module(name)
    assert rows, f"bench_{name}: no figures"
    for row in rows:
        assert row.figure and isinstance(row.value, int | float), row
        assert not math.isinf(row.value), row
