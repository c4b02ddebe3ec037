"""Successive halving (``trials.fidelity: halving``): trials run on to the next rung only when
they are among the best 1/eta there, keep the trajectories they ran, are told to TPE as
failed; per-sequence and joint studies stay deterministic and resumable."""

from __future__ import annotations

import math
from concurrent.futures import Executor
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers.tuning_adapters import DriftAdapter
from helpers.tuning_settings import HALVING, Interrupt, interrupt_after, settings

from pipeline.errors import ConfigError
from pipeline.sequence import SequenceReader
from pipeline.trajectory import read_trajectory
from pipeline.tuning.job import evaluate_trial, trajectory_path
from pipeline.tuning.pruning import (
    Checkpoint,
    HalvingSection,
    StoppingRule,
    rungs,
    running_rte,
    sequence_rungs,
    spread_order,
    value_at,
)
from pipeline.tuning.rung_board import rung_threshold
from pipeline.tuning.smbo import make_job, make_studies, run_trials, study_adapter
from pipeline.tuning.table import trials_path


def table(out: Path, study: str = "seq_a") -> dict[str, list]:
    d = pq.read_table(trials_path(out, "drift", study)).to_pydict()
    return {k: v for k, v in d.items() if k != "wall_time_s"}


def test_rungs_and_their_thresholds() -> None:
    h = HalvingSection(eta=3, rungs=3)
    assert h.fractions() == [1 / 9, 1 / 3]
    assert rungs([90], h) == [Checkpoint((9,)), Checkpoint((29,))]
    # a joint study: every sequence to the same fraction, side by side
    assert rungs([90, 45], h) == [Checkpoint((9, 4)), Checkpoint((29, 14))]
    assert rungs([3], h) == [Checkpoint((0,))]  # 1/3 of 3 frames is frame 0 again: one rung
    # the best 1/eta of the earlier values and the trial's own: the ((|V| + 1) // 3)-th smallest
    assert rung_threshold([5.0, 1.0, 3.0, 2.0, 4.0], 3) == 2.0  # 6 // 3 = 2nd
    assert rung_threshold([4.0, 2.0, math.nan, 9.0], 3) == 2.0  # no value: left out; 4 // 3
    assert rung_threshold([5.0], 3) == 5.0  # too few: the smallest
    assert rung_threshold([], 3) is None and rung_threshold([math.nan], 3) is None
    rule = StoppingRule.of("halving", settings().pruning, h)
    assert rule.told_loss("pruned", 0.5, 100.0) == 100.0  # as failed
    assert rule.told_loss("ok", 0.5, 100.0) == 0.5
    whole = StoppingRule.of("whole", settings(pruning={"percentile": 50.0}).pruning, h)
    assert whole.kind == "percentile" and whole.told_loss("pruned", 0.5, 100.0) == 0.5


def test_a_rung_averages_the_sequences_scored_so_far() -> None:
    """A joint study's short sequence, on which no segment of L has ended by a rung, does not
    make the rung's value NaN (the percentile pruner's values stay NaN there)."""
    def line(n: int, drift: float) -> np.ndarray:
        T = np.tile(np.eye(4), (n, 1, 1))
        T[:, 0, 3] = np.arange(n) * (1.0 + drift)  # 1 m a frame, the estimate scaled
        return T

    gts, ests = [line(30, 0.0), line(12, 0.0)], [line(30, 0.1), line(12, 0.3)]
    point = Checkpoint((9, 3))  # 9 m of the first, 3 m of the second: no 5 m segment there
    first = value_at(Checkpoint((9, -1)), gts, ests, 5.0)
    assert first == pytest.approx(12.0)  # 0.6 m over the first 6 m (more than L = 5 m)
    assert value_at(point, gts, ests, 5.0, scored_only=True) == first
    assert math.isnan(value_at(point, gts, ests, 5.0))
    both = value_at(Checkpoint((9, 11)), gts, ests, 5.0, scored_only=True)
    assert both == pytest.approx(24.0)  # (12 + 36) / 2


def test_trials_stop_at_rungs_and_keep_what_they_ran(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = settings(iterations=16, **HALVING)
    (summary,) = run_trials(sequences[:1], tmp_path, s, seed=5, progress=False, executor=pool)
    t = table(tmp_path)
    pruned = [i for i, st in enumerate(t["status"]) if st == "pruned"]
    assert summary.pruned == len(pruned) >= 4 and set(t["status"]) == {"ok", "pruned"}
    assert t["status"][0] == "ok"  # nothing told yet: the first trial runs whole
    with SequenceReader(sequences[0]) as reader:
        n = len(reader)
    stops = {len(read_trajectory(trajectory_path(tmp_path, "drift", "seq_a", i)))
             for i in pruned}
    assert stops <= {8, 15} and stops  # the rungs: 1/4 and 1/2 of 30 frames
    for i in pruned:
        last = len(read_trajectory(trajectory_path(tmp_path, "drift", "seq_a", i))) - 1
        assert f"pruned at seq_a frame {last}: running RTE" in t["error"][i]
        assert t["objective"][i] < 100.0  # the table holds its value there (TPE: the penalty)
    for i, st in enumerate(t["status"]):
        if st == "ok":
            assert len(read_trajectory(trajectory_path(tmp_path, "drift", "seq_a", i))) == n
    # deterministic: the same seed gives the same table
    run_trials(sequences[:1], tmp_path / "again", s, seed=5, progress=False, executor=pool)
    assert table(tmp_path / "again") == t


def test_a_resumed_halving_study_is_the_uninterrupted_one(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """Rung values come back from the stored (partial) trajectories on resume; 2 workers."""
    s = settings(iterations=14, workers=2, **HALVING)
    with pytest.raises(Interrupt):
        run_trials(sequences[:1], tmp_path / "k", s, seed=8, progress=False,
                   on_trial=interrupt_after(9), executor=pool)
    run_trials(sequences[:1], tmp_path / "k", s, seed=8, progress=False, executor=pool)
    run_trials(sequences[:1], tmp_path / "w", s, seed=8, progress=False, executor=pool)
    whole = table(tmp_path / "w")
    assert "pruned" in whole["status"][9:] and table(tmp_path / "k") == whole
    other = settings(iterations=14, workers=2, fidelity="halving",
                     halving={"eta": 3, "rungs": 3})
    with pytest.raises(ConfigError, match="fidelity"):
        run_trials(sequences[:1], tmp_path / "w", other, seed=8, progress=False,
                   executor=pool)


def test_a_joint_trial_runs_every_sequence_from_the_first_rung(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = settings(iterations=12, **HALVING)
    (joint,) = run_trials(sequences, tmp_path, s, seed=5, joint=True, progress=False,
                          executor=pool)
    t = table(tmp_path, "__joint__")
    assert joint.pruned == t["status"].count("pruned") > 0
    for i, st in enumerate(t["status"]):
        ran = [len(read_trajectory(trajectory_path(tmp_path, "drift", q.stem, i)))
               for q in sequences]
        assert ran == ([30, 30] if st == "ok" else [ran[0], ran[0]]) and ran[0] in (8, 15, 30)


def test_sequence_rungs_run_whole_sequences_spread_over_the_study() -> None:
    """``halving.unit: sequence``: rung r runs the first sequences of the van der Corput order
    that hold its fraction of the frames, whole; nested rungs, none with every sequence."""
    assert spread_order(8) == [0, 4, 2, 6, 1, 5, 3, 7]
    assert spread_order(6) == [0, 3, 1, 4, 2, 5]
    assert sorted(spread_order(13)) == list(range(13))
    h = HalvingSection(eta=3, rungs=3, unit="sequence")
    end, no = 299, -1
    assert rungs([300] * 8, h) == [  # 1/9 of 2400 frames: one sequence; 1/3: three
        Checkpoint((end, no, no, no, no, no, no, no)),
        Checkpoint((end, no, end, no, end, no, no, no))]
    # KITTI's training sequences: 00 alone holds 1/9 of 14,136 frames, 00 and 03 a third
    assert rungs([4541, 1101, 4661, 801, 271, 2761], h) == [
        Checkpoint((4540, no, no, no, no, no)), Checkpoint((4540, no, no, 800, no, no))]
    assert rungs([300], h) == []  # one sequence: the study runs whole
    assert sequence_rungs([10, 10], [0.5, 0.5]) == [Checkpoint((9, -1))]  # no repeated rung
    with pytest.raises(ValueError, match="unit"):
        HalvingSection.model_validate({"unit": "window"})


def test_a_joint_trial_stopped_at_a_sequence_rung_ran_its_sequences_whole(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """eta 2 over two sequences of 30 frames: the one rung is seq_a whole; a trial stopped
    there has seq_a's whole trajectory and none of seq_b, and its value is seq_a's RTE."""
    s = settings(iterations=12, fidelity="halving",
                 halving={"eta": 2, "rungs": 3, "unit": "sequence"})
    (joint,) = run_trials(sequences, tmp_path, s, seed=5, joint=True, progress=False,
                          executor=pool)
    t = table(tmp_path, "__joint__")
    assert joint.pruned == t["status"].count("pruned") > 0
    with SequenceReader(sequences[0]) as reader:
        gt_a = reader.ground_truth()
    for i, st in enumerate(t["status"]):
        a, b = (trajectory_path(tmp_path, "drift", q.stem, i) for q in sequences)
        est_a = read_trajectory(a).T_world_lidar
        assert len(est_a) == 30
        if st == "ok":
            assert len(read_trajectory(b)) == 30
        else:
            assert not b.exists() and "pruned at seq_a frame 29" in t["error"][i]
            # its value there: seq_a's whole RTE
            assert t["objective"][i] == pytest.approx(running_rte(gt_a, est_a, 29, 5.0))


def test_a_trial_streams_from_the_file_as_from_the_cache(
        sequences: list[Path], tmp_path: Path) -> None:
    """A sequence too large for the scan cache is read frame by frame and still stops at its
    rungs: the same outcome and trajectory as from the decoded scans."""
    s = settings(iterations=4, **HALVING)
    adapter = study_adapter(s)
    (study,) = make_studies(sequences[:1], joint=False)
    path = study.sequences[0][1]
    with SequenceReader(path) as reader:
        scans = list(reader)
    drift = DriftAdapter()
    drift.warm(scans)  # the drift adapter finds each scan's truth by stamp
    outcomes = []
    for name, cached in (("file", None), ("cache", {str(Path(path).resolve()): scans})):
        job = make_job(study, adapter, 3, 7, {"bias": 0.9, "gain": 2.0, "window": 1},
                       tmp_path / name, s, checkpoints=((7,), (14,)), thresholds=(None, 0.01))
        out = evaluate_trial(job, drift, cached)
        traj = read_trajectory(trajectory_path(tmp_path / name, "drift", "seq_a", 3))
        outcomes.append((out["status"], out["objective"], out["curve"], traj.T_world_lidar))
    (status, objective, curve, est), other = outcomes
    assert status == "pruned" and len(est) == 15 and len(curve) == 2
    assert (status, objective, curve) == other[:3] and np.array_equal(est, other[3])
