"""Trials lost to the machinery (a process killed from outside, a broken pool) are run again,
never scored; odometry failures keep the penalty; a resumed study proposes what an
uninterrupted one would."""

from __future__ import annotations

from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from helpers.tuning_settings import Interrupt, settings

from pipeline.errors import InfrastructureError
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import trials_path


def rows(out: Path, algorithm: str) -> dict[str, list]:
    d = pq.read_table(trials_path(out, algorithm, "seq_a")).to_pydict()
    return {k: v for k, v in d.items() if k != "wall_time_s"}


def oom_once(tmp_path: Path, **kw: object) -> object:
    """Every parameter set's first run is SIGKILLed (the trial process, or the pool worker
    itself when the trial runs in-process), later runs are the drift adapter's."""
    markers = tmp_path / "markers"
    markers.mkdir(exist_ok=True)
    return settings(algorithm="helpers.tuning_adapters:failing",
                    adapter_options={"mode": "oom_once", "threshold": -2.0,
                                     "marker_dir": str(markers)}, **kw)


def test_a_trial_killed_from_outside_is_run_again_and_scored_as_if_nothing_happened(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    (summary,) = run_trials(sequences[:1], tmp_path / "k", oom_once(tmp_path, iterations=4),
                            seed=6, progress=False, executor=pool)
    run_trials(sequences[:1], tmp_path / "d", settings(iterations=4), seed=6, progress=False,
               executor=pool)
    got = rows(tmp_path / "k", "failing")
    assert got["status"] == ["ok"] * 4 and summary.lost == [] and summary.failed == 0
    assert got == rows(tmp_path / "d", "drift")  # the same proposals and objectives


def test_a_lost_trial_stops_the_study_and_a_resume_runs_it(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = oom_once(tmp_path, iterations=3, retries=0)
    with pytest.raises(InfrastructureError, match=r"1 trial\(s\) lost after 0 retries.*"
                                                  r"trial 0: trial process killed by SIGKILL"):
        run_trials(sequences[:1], tmp_path / "k", s, seed=6, progress=False, executor=pool)
    first = rows(tmp_path / "k", "failing")
    assert first["trial"] == [0] and first["status"] == ["lost"]
    assert first["objective"][0] != first["objective"][0]  # NaN: never the penalty
    (summary,) = run_trials(sequences[:1], tmp_path / "k", s.model_copy(update={"retries": 1}),
                            seed=6, progress=False, executor=pool)
    assert summary.ran == 3 and rows(tmp_path / "k", "failing")["status"] == ["ok"] * 3


def test_a_broken_process_pool_is_replaced_and_its_trials_run_again(
        sequences: list[Path], tmp_path: Path) -> None:
    """Without a time limit trials run in the pool worker: SIGKILL breaks the pool."""
    s = oom_once(tmp_path, iterations=2, time_limit_s=None)
    (summary,) = run_trials(sequences[:1], tmp_path / "k", s, seed=6, progress=False)
    assert rows(tmp_path / "k", "failing")["status"] == ["ok", "ok"] and summary.ran == 2


def test_a_resumed_parallel_study_proposes_what_an_uninterrupted_one_does(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """With two trials in flight (lag 3) trial t is proposed with t-2 and t-1 still pending.
    The run is killed right after a new best trial finishes: a resume that showed it to the
    next proposals as finished would propose other parameters than the uninterrupted run."""
    s = settings(algorithm="helpers.tuning_adapters:sleepy", workers=2, iterations=12,
                 startup_trials=2)
    best: list[float] = []

    def stop_at_a_new_best(study: object, result: object) -> None:
        objective, trial = result.objective, result.trial  # type: ignore[attr-defined]
        if trial >= 3 and objective < min(best):
            raise Interrupt
        best.append(objective)

    with pytest.raises(Interrupt):
        run_trials(sequences[:1], tmp_path / "k", s, seed=12, progress=False,
                   on_trial=stop_at_a_new_best, executor=pool)
    run_trials(sequences[:1], tmp_path / "k", s, seed=12, progress=False, executor=pool)
    run_trials(sequences[:1], tmp_path / "w", s, seed=12, progress=False, executor=pool)
    assert rows(tmp_path / "k", "sleepy") == rows(tmp_path / "w", "sleepy")



def test_sigkill_of_adaptune_trials_then_a_resume_loses_and_repeats_nothing(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """`adaptune trials` SIGKILLed mid-study (a real process, two trials in flight), then run
    again: its trials table equals an uninterrupted run's, trial for trial (parameters,
    status, objective)."""
    import json
    import os
    import signal
    import subprocess
    import sys
    import time

    s = settings(algorithm="helpers.tuning_adapters:sleepy", workers=2, iterations=10,
                 startup_trials=2)
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({"base": {"seed": 5, "length_m": s.length_m}, "trials": {
        **{k: getattr(s, k) for k in ("algorithm", "iterations", "workers", "startup_trials",
                                      "time_limit_s")}, "pruning": s.pruning.model_dump()}}))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).parents[1]), *filter(None, [os.environ.get("PYTHONPATH")])])}
    table = trials_path(tmp_path / "k", "sleepy", "seq_a")
    killed = subprocess.Popen([sys.executable, "-m", "stages.cli", "trials", str(sequences[0]),
                               "--out", str(tmp_path / "k"), "--params", str(params)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not (table.exists() and pq.read_metadata(table).num_rows >= 3):
            assert killed.poll() is None, killed.stderr.read()  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "no trials written"
            time.sleep(0.05)
        os.kill(killed.pid, signal.SIGKILL)
        killed.wait(30)
    finally:
        if killed.poll() is None:
            killed.kill()
            killed.wait()
    assert 3 <= len(rows(tmp_path / "k", "sleepy")["trial"]) < 10
    for out in (tmp_path / "k", tmp_path / "w"):  # the resume; an uninterrupted run
        run_trials(sequences[:1], out, s, seed=5, progress=False, executor=pool)
    resumed = rows(tmp_path / "k", "sleepy")
    assert resumed["trial"] == list(range(10)) and set(resumed["status"]) == {"ok"}
    assert resumed == rows(tmp_path / "w", "sleepy")
