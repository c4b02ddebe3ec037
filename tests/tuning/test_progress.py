"""Without a terminal (``dvc repro`` in CI) a study logs its progress in lines."""

from __future__ import annotations

import logging
import re
from concurrent.futures import Executor
from pathlib import Path

import pytest
from conftest import settings

from pipeline.tuning.smbo import run_trials


def test_a_study_without_a_terminal_logs_done_failed_best_and_eta(
        sequences: list[Path], pool: Executor, tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    s = settings(algorithm="tuning_adapters:failing", iterations=20,
                 adapter_options={"mode": "raise", "threshold": 0.0})
    with caplog.at_level(logging.INFO, logger="pipeline.progress"):
        run_trials(sequences[:1], tmp_path, s, seed=3, progress=True, executor=pool)
    lines = [r.getMessage() for r in caplog.records if r.name == "pipeline.progress"]
    assert lines[0] == "trials failing seq_a: 20 trials, 0 finished before"
    steps = lines[1:-1]  # one line every 2 trials (a tenth of the study), but the last
    assert len(steps) == 9
    assert re.fullmatch(r"trials failing seq_a: 2/20 done, [12] failed, 0 pruned, 0 lost, "
                        r"(best [\d.]+ % \(trial \d+\)|no ok trial yet), ETA \d+ s", steps[0])
    assert re.fullmatch(r"trials failing seq_a finished: 20/20 done, \d+ failed, 0 pruned, "
                        r"0 lost, best [\d.]+ % \(trial \d+\), done in \d+ s \(20 run now\)",
                        lines[-1])
