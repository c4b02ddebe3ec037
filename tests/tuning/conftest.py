"""Fixtures of the tuner tests: tiny sequences and one shared process pool."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # tuning_adapters, also for spawned workers

import tuning_adapters

from pipeline.executor import open_executor
from pipeline.tuning.smbo import TrialsSection


@pytest.fixture(scope="session")
def sequences(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two small sequences with ground truth (30 frames, 1 m a frame)."""
    root = tmp_path_factory.mktemp("sequences")
    return [
        tuning_adapters.write_sequence(root / "seq_a.mcap", seed=0),
        tuning_adapters.write_sequence(root / "seq_b.mcap", yaw_rate=-0.05, seed=1),
    ]


@pytest.fixture(scope="session")
def pool() -> Iterator[Executor]:
    """One spawn process pool of 2 workers shared by the tests (spawning is the slow part)."""
    with open_executor(2) as ex:
        yield ex


def settings(**kw: object) -> TrialsSection:
    """Small, fast settings for the drift adapter (no pruning unless asked for)."""
    base: dict[str, object] = dict(
        algorithm="tuning_adapters:drift",
        iterations=6,
        workers=1,
        startup_trials=3,
        length_m=5.0,
        time_limit_s=20.0,
        pruning={"percentile": None},
    )
    base.update(kw)
    return TrialsSection(**base)


class Interrupt(KeyboardInterrupt):
    """Ctrl-C in the middle of a study (raised by an ``on_trial`` callback)."""


def interrupt_after(n: int) -> Callable[[object, object], None]:
    """An ``on_trial`` callback of ``run_trials`` that interrupts the run after its n-th
    finished trial."""
    seen: list[int] = []

    def on_trial(study: object, result: object) -> None:
        seen.append(result.trial)  # type: ignore[attr-defined]
        if len(seen) == n:
            raise Interrupt

    return on_trial
