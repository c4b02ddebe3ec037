"""Fixtures of the tuner tests: tiny sequences and one shared process pool."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from concurrent.futures import Executor
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1]))  # helpers, also for spawned workers

import helpers.tuning_adapters as tuning_adapters

from pipeline.executor import open_executor


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
