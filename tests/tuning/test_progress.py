"""Without a terminal (``dvc repro`` in CI) a study logs its progress in lines."""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
from concurrent.futures import Executor
from pathlib import Path

import pytest
from helpers.tuning_settings import settings

from pipeline.tuning.smbo import run_trials


def test_a_study_without_a_terminal_logs_done_failed_best_and_eta(
        sequences: list[Path], pool: Executor, tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    s = settings(algorithm="helpers.tuning_adapters:failing", iterations=20,
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


def test_adaptune_trials_without_a_terminal_prints_progress_lines_at_default_verbosity(
        sequences: list[Path], tmp_path: Path) -> None:
    """What a `dvc repro` user sees: `adaptune trials` with stderr a pipe and no -v logs a
    line every tenth of a study (done, failed, pruned, best, ETA) and one when it ends."""
    params = tmp_path / "params.yaml"
    params.write_text(
        "trials: {algorithm: 'helpers.tuning_adapters:drift', iterations: 20, workers: 1, "
        "startup_trials: 3, time_limit_s: 20.0, "
        "pruning: {percentile: 50.0, checkpoints: 5, warmup: 0.2, min_trials: 3}}\n"
        "base: {length_m: 5.0}\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).parents[1]), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-m", "stages.cli", "trials", str(sequences[0]), "--out",
         str(tmp_path / "out"), "--params", str(params)],
        capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = [x.removeprefix("INFO pipeline.progress: ") for x in done.stderr.splitlines()
             if x.startswith("INFO pipeline.progress: ")]
    assert lines[0] == "trials drift seq_a: 20 trials, 0 finished before"
    assert len(lines) == 11  # the start, every 2 trials but the last, the end
    for line in lines[1:-1]:
        assert re.fullmatch(r"trials drift seq_a: \d+/20 done, 0 failed, \d+ pruned, 0 lost, "
                            r"best [\d.]+ % \(trial \d+\), ETA (\d+ s|[\d.]+ min)", line), line
    end = re.fullmatch(r"trials drift seq_a finished: 20/20 done, 0 failed, (\d+) pruned, "
                       r"0 lost, best [\d.]+ % \(trial \d+\), done in \d+ s \(20 run now\)",
                       lines[-1])
    assert end and int(end.group(1)) > 0, lines[-1]
