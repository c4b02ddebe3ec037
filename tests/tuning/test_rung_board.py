"""The rung board (``pipeline.tuning.rung_board``): a trial at a rung of successive halving is
ranked against every earlier trial there, waiting for those still running, so its threshold
depends on trial ids, not on the workers or on which trial finished first."""

from __future__ import annotations

import logging
import math
import threading
import time
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from helpers.tuning_settings import HALVING, settings

from pipeline.tuning.rung_board import RungBoard
from pipeline.tuning.smbo import make_job, make_studies, run_trials, study_adapter
from pipeline.tuning.table import trials_path
from pipeline.tuning.worker import WorkerState


def later(seconds: float, action: object) -> threading.Thread:
    """Run ``action()`` in a thread after ``seconds``."""
    def run() -> None:
        time.sleep(seconds)
        action()  # type: ignore[operator]

    thread = threading.Thread(target=run)
    thread.start()
    return thread


def test_a_trial_waits_at_its_rung_for_every_earlier_trial(tmp_path: Path) -> None:
    board = RungBoard(str(tmp_path / "rungs"))
    board.post(0, [1.0, 0.5], ended=True)
    board.post(1, [3.0], ended=True)  # stopped at rung 0: out of rung 1
    board.post(2, [2.0, math.nan])  # no segment ended by rung 1: no value there
    board.post(3, [4.0])  # still running towards rung 1
    assert board.threshold(4, 0, 2) == 2.0  # every earlier trial is past rung 0: no wait
    waits: list[float] = []
    thread = later(0.4, lambda: board.post(3, [4.0, 0.2]))
    t0 = time.monotonic()
    limit = board.threshold(4, 1, 2, on_wait=waits.append)
    waited = time.monotonic() - t0
    thread.join()
    assert limit == 0.2  # V = {0.5, 0.2}: the (3 // 2)-th smallest
    assert waited >= 0.4 and sum(waits) == pytest.approx(waited, abs=0.05)
    board.end(2)  # stopped at rung 1
    thread = later(0.3, lambda: board.end(3))  # a trial that fails before rung 2
    assert board.threshold(4, 2, 2) is None  # nobody reached rung 2
    thread.join()


def test_a_trial_stuck_before_the_rung_is_left_out_after_the_wait_limit(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    board = RungBoard(str(tmp_path))
    board.post(0, [1.0], ended=True)
    board.post(1, [])  # started, never reaches rung 0 (or queued: no post at all, trial 2)
    with caplog.at_level(logging.WARNING):
        assert board.threshold(3, 0, 2, wait_limit_s=0.2) == 1.0
    assert "trials [1, 2] did not reach it" in caplog.text


def test_a_resume_keeps_the_posts_of_finished_trials_only(tmp_path: Path) -> None:
    board = RungBoard(str(tmp_path))
    for trial in (0, 1, 2, 5):
        board.post(trial, [float(trial)])
    board.keep({0: (9.0,), 3: (2.0, 1.0)})  # 1, 2, 5 were in flight when the run was killed
    assert board.read(0) is not None and board.read(0).values == (0.0,)  # as it posted
    assert board.read(3) is not None and board.read(3).ended
    assert board.read(3).values == (2.0, 1.0)  # posted from its stored curve
    assert [board.read(t) for t in (1, 2, 5)] == [None, None, None]


def trials(out: Path) -> dict[str, list]:
    d = pq.read_table(trials_path(out, "drift", "seq_a")).to_pydict()
    return {k: d[k] for k in ("trial", "status", "objective")}


def test_a_many_worker_study_ranks_its_first_trials_and_is_timing_free(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """8 workers: the proposals lag 15 trials, the rungs do not. Thresholds from the finished
    trials alone would run trials 1..14 whole; here they are ranked from trial 1 on, and the
    study is the same one trial at a time as on two processes with 8 trials in flight."""
    s = settings(iterations=12, workers=8, **HALVING)
    with ThreadPoolExecutor(1) as one:
        run_trials(sequences[:1], tmp_path / "serial", s, seed=3, progress=False, executor=one)
    serial = trials(tmp_path / "serial")
    assert serial["status"].count("pruned") >= 3
    run_trials(sequences[:1], tmp_path / "pool", s, seed=3, progress=False, executor=pool)
    assert trials(tmp_path / "pool") == serial


WAIT_LIMIT_S = 4.0


def test_waiting_at_a_rung_does_not_count_against_the_time_limit(
        sequences: list[Path], tmp_path: Path) -> None:
    """A trial in a trial server (time limit 4 s) waits 6 s at its first rung for trial 0:
    it is not killed, and then stops there or goes on. (A wait longer than the limit and
    shorter than twice it, after which a wait gives up; the trial's own work, 0.1 s idle, has
    40 times the margin on a loaded machine.)"""
    s = settings(iterations=2, time_limit_s=WAIT_LIMIT_S, **HALVING)
    (study,) = make_studies(sequences[:1], joint=False)
    board = RungBoard(str(tmp_path / "rungs"))
    job = make_job(study, study_adapter(s), 1, 7, {"bias": 0.9, "gain": 2.0, "window": 1},
                   tmp_path, s, checkpoints=((7,), (14,)), thresholds=(None, None),
                   scored_only=True, rungs=board, eta=2)
    state = WorkerState()
    try:
        state.warm(job)
        thread = later(1.5 * WAIT_LIMIT_S, lambda: board.post(0, [0.0, 0.0, 0.0], ended=True))
        result = state.run(job)
        thread.join()
    finally:
        state.close()
    assert result.status == "pruned", result.error  # behind trial 0's perfect values
    assert result.wall_time_s > 1.5 * WAIT_LIMIT_S and board.read(1).ended


def test_a_trial_with_no_value_at_a_rung_does_not_wait_there(
        sequences: list[Path], tmp_path: Path) -> None:
    """At frame 1 no segment of L = 5 m has ended: the value is NaN, which no threshold stops,
    so the trial does not wait for trial 0 (which never posts) and runs to the end."""
    s = settings(iterations=2, time_limit_s=None, **HALVING)
    (study,) = make_studies(sequences[:1], joint=False)
    board = RungBoard(str(tmp_path / "rungs"))
    job = make_job(study, study_adapter(s), 1, 7, {"bias": 0.0, "gain": 1.0, "window": 1},
                   tmp_path, s, checkpoints=((1,),), thresholds=(None,), scored_only=True,
                   rungs=board, eta=2)
    results: list[object] = []
    runner = threading.Thread(target=lambda: results.append(WorkerState().run(job)),
                              daemon=True)  # a trial that waited would wait for ever
    runner.start()
    runner.join(timeout=60)
    assert results and results[0].status == "ok", results  # type: ignore[attr-defined]
    post = board.read(1)
    assert post is not None and post.ended and math.isnan(post.values[0])
