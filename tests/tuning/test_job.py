"""One trial with a time limit: the worker's trial server (reuse, kill on timeout, death)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from pipeline.tuning.job import TrialJob
from pipeline.tuning.worker import WorkerState


def make_job(sequence: Path, out: Path, trial: int, fails: str | None = None,
             bias: float = 0.1, limit_s: float = 10.0) -> TrialJob:
    """A drift trial, or (``fails`` = a mode) a trial of the failing adapter."""
    return TrialJob(adapter=f"helpers.tuning_adapters:{'failing' if fails else 'drift'}",
                    algorithm="drift", sequences=(("seq_a", str(sequence)),), trial=trial,
                    seed=trial, params={"bias": bias, "gain": 1.0, "window": 3.0},
                    out_dir=str(out), length_m=5.0, penalty_pct=100.0, jump_limit_m=5.0,
                    time_limit_s=limit_s, adapter_options={"mode": fails} if fails else {})


@pytest.fixture
def state() -> Iterator[WorkerState]:
    s = WorkerState()
    yield s
    s.close()


def server_pid(state: WorkerState) -> int:
    assert len(state.idle) == 1 and state.idle[0].alive()
    return int(state.idle[0].proc.pid)


def test_trials_of_a_study_share_one_server_process(sequences: list[Path], tmp_path: Path,
                                                    state: WorkerState) -> None:
    first = state.run(make_job(sequences[0], tmp_path, 0))
    pid = server_pid(state)
    second = state.run(make_job(sequences[0], tmp_path, 1, bias=0.3))
    assert first.status == second.status == "ok"
    assert server_pid(state) == pid
    assert second.objective != first.objective
    other = state.run(make_job(sequences[1], tmp_path, 2))  # other scans: a new server
    assert other.status == "ok" and server_pid(state) != pid


def test_a_hung_trial_kills_the_server_and_the_next_trial_gets_a_new_one(
        sequences: list[Path], tmp_path: Path, state: WorkerState) -> None:
    state.run(make_job(sequences[0], tmp_path, 0))
    pid = server_pid(state)
    hung = state.run(make_job(sequences[0], tmp_path, 1, "hang", bias=0.5, limit_s=1.0))
    assert hung.status == "failed" and "time limit of 1 s exceeded" in hung.error
    assert not state.idle
    after = state.run(make_job(sequences[0], tmp_path, 2))
    assert after.status == "ok" and server_pid(state) != pid


def test_a_trial_that_kills_its_process_is_a_failed_trial(sequences: list[Path],
                                                         tmp_path: Path,
                                                         state: WorkerState) -> None:
    died = state.run(make_job(sequences[0], tmp_path, 0, "exit", bias=0.5))
    assert died.status == "failed" and died.error == "trial process died (exit code 3)"
    assert state.run(make_job(sequences[0], tmp_path, 1)).status == "ok"


def test_a_trial_process_killed_from_outside_is_lost_not_failed(
        sequences: list[Path], tmp_path: Path, state: WorkerState) -> None:
    """SIGKILL as the OOM killer sends it: an infrastructure failure, never scored."""
    lost = state.run(make_job(sequences[0], tmp_path, 0, "oom", bias=0.5))
    assert lost.status == "lost" and "killed by SIGKILL" in lost.error
    assert lost.objective != lost.objective  # NaN: no penalty
    assert state.run(make_job(sequences[0], tmp_path, 1)).status == "ok"
