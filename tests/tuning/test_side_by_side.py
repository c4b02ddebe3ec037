"""Studies side by side (``pipeline.tuning.smbo.side_by_side``): on a pool of its own, each of
the W workers runs one study at a time, so a study's sequences are decoded and warmed once,
not once per worker; the trials and their results are those of the studies run one after
another on one pool of W workers."""

from __future__ import annotations

import logging
from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from helpers import tuning_adapters
from helpers.tuning_settings import HALVING, settings

from pipeline.tuning.smbo import run_trials, side_by_side
from pipeline.tuning.table import trials_path


def four_sequences(root: Path) -> list[Path]:
    root.mkdir()
    return [tuning_adapters.write_sequence(root / f"s{i}.mcap", n_frames=20 + 5 * i,
                                           yaw_rate=0.02 * (i - 1.5), seed=i) for i in range(4)]


def tables(out: Path, names: list[str]) -> dict[str, dict[str, list]]:
    return {n: {k: v for k, v in pq.read_table(trials_path(out, "warm_log", n)).to_pydict().items()
                if k != "wall_time_s"} for n in names}


def test_each_study_is_warmed_by_one_worker_with_the_results_of_one_shared_pool(
        pool: Executor, tmp_path: Path) -> None:
    sequences = four_sequences(tmp_path / "sequences")
    names = [p.stem for p in sequences]
    logs = {how: tmp_path / f"warms_{how}" for how in ("shared", "side")}
    for folder in logs.values():
        folder.mkdir()

    def study_settings(how: str) -> object:
        return settings(algorithm="helpers.tuning_adapters:warm_log", workers=2, iterations=8,
                        startup_trials=3, adapter_options={"log_dir": str(logs[how])})

    shared = run_trials(sequences, tmp_path / "shared", study_settings("shared"), seed=5,
                        progress=False, executor=pool)
    side = run_trials(sequences, tmp_path / "side", study_settings("side"), seed=5,
                      progress=False)
    assert tables(tmp_path / "side", names) == tables(tmp_path / "shared", names)
    assert [s.sequence for s in side] == [s.sequence for s in shared] == names
    assert [s.best_params for s in side] == [s.best_params for s in shared]
    warmed = {how: [f.read_text() for f in folder.glob("*.warm")] for how, folder in logs.items()}
    assert len(set(warmed["side"])) == len(set(warmed["shared"])) == 4  # every study, warmed
    assert len(warmed["shared"]) == 8  # by both workers of the shared pool
    # side by side once each; the worker left without a study takes trials of the last one
    assert len(warmed["side"]) <= 5


def test_side_by_side_only_on_a_pool_of_its_own_without_halving(pool: Executor) -> None:
    assert side_by_side(settings(workers=2), 12, None) == 2
    assert side_by_side(settings(workers=3), 2, None) == 2
    assert side_by_side(settings(workers=2), 1, None) == 1  # the joint study
    assert side_by_side(settings(workers=1), 12, None) == 1
    assert side_by_side(settings(workers=2), 12, pool) == 1  # a given executor
    assert side_by_side(settings(workers=2, dask="local"), 12, None) == 1
    assert side_by_side(settings(workers=2, **HALVING), 12, None) == 1  # trials wait at rungs


def test_a_study_side_by_side_logs_its_end_when_it_ends(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Three studies on two lanes: the third starts when one of the first two has ended, and
    that one's "finished" line comes before the third's first line."""
    sequences = four_sequences(tmp_path / "sequences")[:3]
    s = settings(workers=2, iterations=6)
    with caplog.at_level(logging.INFO, logger="pipeline.progress"):
        run_trials(sequences, tmp_path / "out", s, seed=3, progress=True)
    lines = [r.getMessage() for r in caplog.records if r.name == "pipeline.progress"]
    starts = [i for i, line in enumerate(lines) if line.endswith("6 trials, 0 finished before")]
    ends = [i for i, line in enumerate(lines) if " finished: 6/6 done" in line]
    assert len(starts) == len(ends) == 3
    assert ends[0] < starts[2]
