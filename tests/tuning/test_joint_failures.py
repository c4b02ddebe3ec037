"""A joint study whose sequences fail on their own (``fixed.failures``, issue 54): under
``trial`` one failed sequence fails the trial; under ``sequence`` it counts at the penalty in
the mean over the sequences, whole, pruned (percentile) and halved, and a resume restores what
the trials recorded."""

from __future__ import annotations

from concurrent.futures import Executor
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest
from helpers.tuning_adapters import write_sequence
from helpers.tuning_settings import settings

from pipeline.config import validate_section
from pipeline.errors import ConfigError
from pipeline.metrics.rte import mean_rte_pct
from pipeline.sequence import read_ground_truth
from pipeline.trajectory import read_trajectory
from pipeline.tuning.job import TrialResult, trajectory_path
from pipeline.tuning.layout import read_trial_trajectories
from pipeline.tuning.rung_board import RungBoard
from pipeline.tuning.section import FixedSection, TrialsSection, joint_settings
from pipeline.tuning.smbo import make_studies, run_trials, study_adapter, study_pruner
from pipeline.tuning.table import read_study, read_trials, trials_path

PENALTY = 300.0
PRUNING = {"percentile": 50.0, "checkpoints": 4, "warmup": 0.0, "min_trials": 1}
"""A percentile pruner that checks from the second trial on (3 checkpoints a sequence)."""


@pytest.fixture(scope="module")
def far(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sequence of 10 m steps (30 frames, stamps after the conftest's): every drift
    trajectory of it jumps more than the 5 m jump limit of ``settings()``, the fenced adapter
    at 100 m leaves it part-way; the conftest's sequences (1 m steps) do neither."""
    return write_sequence(tmp_path_factory.mktemp("far") / "seq_far.mcap", step_m=10.0, seed=2,
                          first_stamp_ns=10**12)


def rows(out: Path, algorithm: str = "drift") -> dict[str, list[Any]]:
    return pq.read_table(trials_path(out, algorithm, "__joint__")).to_pydict()


def rte_of(out: Path, algorithm: str, sequence: Path, trial: int) -> float:
    """RTE [%] at L = 5 m of the stored trajectory of ``sequence`` in ``trial``."""
    est = read_trajectory(trajectory_path(out, algorithm, sequence.stem, trial))
    return mean_rte_pct(read_ground_truth(sequence, "test"), est.T_world_lidar, 5.0)


def run(paths: list[Path], out: Path, s: TrialsSection, pool: Executor) -> list[TrialResult]:
    """The joint study of ``paths`` into ``out``; its results as the trials finished."""
    results: list[TrialResult] = []
    run_trials(paths, out, s, seed=3, joint=True, progress=False, executor=pool,
               on_trial=lambda _, r: results.append(r))
    return sorted(results, key=lambda r: r.trial)


def test_a_sequence_no_set_finishes_fails_every_trial_or_counts_at_the_penalty(
        sequences: list[Path], far: Path, pool: Executor, tmp_path: Path) -> None:
    """Whole trials: under ``trial`` every joint trial fails (the fold's defaults would stand
    in); under ``sequence`` every one is ok, at the mean of the other sequence's RTE and the
    penalty, seq_far with no trajectory and named in the error."""
    s = settings(iterations=4, penalty_pct=PENALTY)
    run([sequences[0], far], tmp_path / "trial", s, pool)
    whole = rows(tmp_path / "trial")
    assert set(whole["status"]) == {"failed"} and set(whole["objective"]) == {PENALTY}
    assert all(e.startswith("implausible jump") for e in whole["error"])

    alone = s.model_copy(update={"failures": "sequence"})
    results = run([sequences[0], far], tmp_path / "seq", alone, pool)
    t = rows(tmp_path / "seq")
    assert t["status"] == ["ok"] * 4
    for tid, objective, error in zip(t["trial"], t["objective"], t["error"], strict=True):
        rte_a = rte_of(tmp_path / "seq", "drift", sequences[0], tid)
        assert objective == pytest.approx((rte_a + PENALTY) / 2, rel=1e-12)
        assert not trajectory_path(tmp_path / "seq", "drift", "seq_far", tid).exists()
        assert error.startswith("1 of 2 sequences failed, each at the penalty 300 % (seq_far): "
                                "seq_far: implausible jump of ")
    assert [set(r.rte_pct) for r in results] == [{"seq_a"}] * 4
    assert read_study(trials_path(tmp_path / "seq", "drift", "__joint__"))["failures"] == \
        "sequence"
    assert "failures" not in read_study(trials_path(tmp_path / "trial", "drift", "__joint__"))


def test_a_trial_whose_every_sequence_fails_still_fails(
        sequences: list[Path], far: Path, pool: Executor, tmp_path: Path) -> None:
    other = write_sequence(tmp_path / "seq_far2.mcap", step_m=10.0, seed=3,
                           first_stamp_ns=2 * 10**12)
    s = settings(iterations=2, penalty_pct=PENALTY, failures="sequence")
    run([far, other], tmp_path / "out", s, pool)
    t = rows(tmp_path / "out")
    assert t["status"] == ["failed"] * 2 and t["objective"] == [PENALTY] * 2
    assert all(e.startswith("every sequence failed (seq_far, seq_far2): seq_far: implausible "
                            "jump of ") and "; seq_far2: implausible jump of " in e
               for e in t["error"])


def test_a_pruned_joint_study_counts_the_failed_sequence_and_resumes_its_curves(
        sequences: list[Path], far: Path, pool: Executor, tmp_path: Path) -> None:
    """Percentile pruning, trials run checkpoint by checkpoint: seq_far (first) fails at its
    end and counts at the penalty from the next checkpoint on; no trial fails; an ok trial's
    objective is the mean with the penalty; the curves the trials recorded are those a resume
    restores from the stored trajectories (the failed sequence at the penalty wherever it ran)."""
    s = settings(iterations=8, penalty_pct=PENALTY, pruning=PRUNING, time_limit_s=None,
                 failures="sequence")
    results = run([far, sequences[0]], tmp_path / "out", s, pool)
    statuses = [r.status for r in results]
    assert "failed" not in statuses and "ok" in statuses and "pruned" in statuses
    for r in results:
        assert "seq_far" in r.error or r.status == "pruned"
        if r.status == "ok":
            rte_a = rte_of(tmp_path / "out", "drift", sequences[0], r.trial)
            assert r.objective == pytest.approx((rte_a + PENALTY) / 2, rel=1e-12)
            # 3 checkpoints in seq_far, its end, 3 in seq_a: seq_far at the penalty in all
            assert r.curve[:4] == (PENALTY,) * 4 and len(r.curve) == 7
            assert all(PENALTY / 2 < v < PENALTY for v in r.curve[4:])
    study = make_studies([far, sequences[0]], joint=True)[0]
    table = trials_path(tmp_path / "out", "drift", "__joint__")
    stored = {r.trial: r for r in read_trials(table, study_adapter(s).space)}
    restored = study_pruner(study, s).restore(
        stored, lambda tid: read_trial_trajectories(tmp_path / "out", "drift", study.sequences,
                                                    tid))
    assert [restored[r.trial].curve for r in results] == [r.curve for r in results]


def test_a_halved_joint_study_counts_a_sequence_failed_part_way_from_the_next_rung_on(
        sequences: list[Path], far: Path, pool: Executor, tmp_path: Path) -> None:
    """Successive halving (rungs at frames 7 and 14, the sequences side by side): seq_far
    leaves the fence at frame 11, runs no further and counts at the penalty from rung 1 on;
    the rung board keeps the values as posted; an ok trial's objective is the mean with the
    penalty."""
    s = settings(algorithm="helpers.tuning_adapters:fenced", adapter_options={"fence_m": 100.0},
                 iterations=6, penalty_pct=PENALTY, fidelity="halving",
                 halving={"eta": 2, "rungs": 3}, time_limit_s=None, failures="sequence")
    results = run([sequences[0], far], tmp_path / "out", s, pool)
    board = RungBoard(str(tmp_path / "out" / "rungs" / "algorithm=fenced" / "sequence=__joint__"))
    assert {r.status for r in results} == {"ok", "pruned"}
    for r in results:
        post = board.read(r.trial)
        assert post is not None and post.ended and post.values == r.curve
        far_path = trajectory_path(tmp_path / "out", "fenced", "seq_far", r.trial)
        if len(r.curve) == 1:  # stopped at rung 0, before seq_far left the fence
            assert r.status == "pruned" and "sequences failed" not in r.error
            assert len(read_trajectory(far_path)) == 8
            continue
        assert "seq_far: RuntimeError: left the 100 m fence at frame 11" in r.error
        assert not far_path.exists()
        assert r.curve[0] < PENALTY / 2 < r.curve[1] < PENALTY  # seq_far ran to frame 7
        if r.status == "ok":
            rte_a = rte_of(tmp_path / "out", "fenced", sequences[0], r.trial)
            assert r.objective == pytest.approx((rte_a + PENALTY) / 2, rel=1e-12)


def test_the_rule_is_the_joint_studys_setting_and_a_study_of_another_is_not_resumed(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """``fixed.failures`` reaches the joint study's settings (``trial`` by default); an
    unknown rule is refused naming the allowed ones; a study run under one rule is not resumed
    under the other."""
    trials = TrialsSection()
    assert joint_settings(trials, FixedSection()).failures == "trial"
    fixed = validate_section(FixedSection, "fixed", {"failures": "sequence"})
    assert joint_settings(trials, fixed).failures == "sequence"
    with pytest.raises(ConfigError, match=r"^fixed\.failures: Input should be 'trial' or "
                       r"'sequence', got 'unit'$"):
        validate_section(FixedSection, "fixed", {"failures": "unit"})
    s = settings(iterations=1, failures="sequence")
    run(sequences, tmp_path / "out", s, pool)
    with pytest.raises(ConfigError, match=r'failures "trial", stored "sequence"'):
        run(sequences, tmp_path / "out", s.model_copy(update={"failures": "trial"}), pool)
