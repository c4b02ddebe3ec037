"""The percentile pruner: hopeless trials stop at a checkpoint, keep the trajectory they ran,
tell the search their running RTE; the study stays deterministic and resumable."""

from __future__ import annotations

import json
from concurrent.futures import Executor
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from helpers.tuning_settings import Interrupt, interrupt_after, settings

from pipeline.sequence import SequenceReader
from pipeline.trajectory import read_trajectory
from pipeline.tuning.job import trajectory_path
from pipeline.tuning.pruning import Checkpoint, PruningSection, checkpoints, thresholds
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import trials_path

PRUNING = {"percentile": 50.0, "checkpoints": 5, "warmup": 0.2, "min_trials": 3}


def table(out: Path, study: str = "seq_a") -> dict[str, list]:
    d = pq.read_table(trials_path(out, "drift", study)).to_pydict()
    return {k: v for k, v in d.items() if k != "wall_time_s"}


def running_rte_by_loop(gt: np.ndarray, est: np.ndarray, last: int, length_m: float) -> float:
    """Reference: mean |translation error| / L of every segment i -> j with j <= last, where
    j is the first frame more than L along the ground-truth path from i (plain loops)."""
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0),
                                                           axis=1))])
    errs = []
    for i in range(last + 1):
        j = next((j for j in range(i, len(gt)) if dist[j] > dist[i] + length_m), None)
        if j is None or j > last:
            continue
        d_gt = np.linalg.inv(gt[i]) @ gt[j]
        d_est = np.linalg.inv(est[i]) @ est[j]
        errs.append(np.linalg.norm((np.linalg.inv(d_est) @ d_gt)[:3, 3]) / length_m * 100)
    return float(np.mean(errs))


def test_checkpoints_and_thresholds() -> None:
    s = PruningSection(**PRUNING)
    assert checkpoints([30], s) == [Checkpoint((k,)) for k in (5, 11, 17, 23)]
    assert checkpoints([10, 20], s) == [*(Checkpoint((k, -1)) for k in (1, 3, 5, 7, 9)),
                                        *(Checkpoint((9, k)) for k in (3, 7, 11, 15))]
    points = checkpoints([30], s)
    curves = [(1.0, 2.0, 3.0, 4.0), (3.0, 4.0, 5.0, 6.0), (2.0, 3.0, 4.0, 5.0)]
    assert thresholds(points, [30], curves, s) == (2.0, 3.0, 4.0, 5.0)  # the medians
    late = PruningSection(**{**PRUNING, "warmup": 0.3})  # frame 5 is 20 % of 30: not yet
    assert thresholds(points, [30], curves, late) == (None, 3.0, 4.0, 5.0)
    assert thresholds(points, [30], curves[:2], s) == (None,) * 4  # fewer than min_trials
    off = PruningSection(**{**PRUNING, "percentile": None})
    assert thresholds(points, [30], curves, off) == (None,) * 4


def test_hopeless_trials_are_pruned_and_keep_what_they_ran(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = settings(iterations=16, pruning=PRUNING)
    (summary,) = run_trials(sequences[:1], tmp_path, s, seed=5, progress=False, executor=pool)
    t = table(tmp_path)
    pruned = [i for i, st in enumerate(t["status"]) if st == "pruned"]
    assert pruned and summary.pruned == len(pruned) and summary.failed == 0
    assert set(t["status"]) == {"ok", "pruned"} and min(pruned) >= 4  # 3 told trials needed
    with SequenceReader(sequences[0]) as reader:
        gt = reader.ground_truth()
    for i in pruned:
        est = read_trajectory(trajectory_path(tmp_path, "drift", "seq_a", i))
        frames = len(est)
        assert frames < len(gt) and list(est.frames) == list(range(frames))
        last = frames - 1
        assert f"pruned at seq_a frame {last}: running RTE" in t["error"][i]
        # the objective is the running RTE over the segments that end by the last frame run
        assert t["objective"][i] == pytest.approx(
            running_rte_by_loop(gt, est.T_world_lidar, last, 5.0), rel=1e-9)
    best = min(o for o, st in zip(t["objective"], t["status"], strict=True) if st == "ok")
    assert summary.best_objective == best
    # deterministic: the same seed gives the same table; a killed run resumed, too
    run_trials(sequences[:1], tmp_path / "again", s, seed=5, progress=False, executor=pool)
    assert table(tmp_path / "again") == t


def test_the_rows_a_pruned_trial_earned_reach_the_results_database(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    import duckdb

    from pipeline.database.store import build_database
    from pipeline.metrics.section import DevkitSection

    out = tmp_path / "trials"
    run_trials(sequences[:1], out, settings(iterations=12, pruning=PRUNING), seed=5,
               progress=False, executor=pool)
    t = table(out)
    pruned = [i for i, st in enumerate(t["status"]) if st == "pruned"]
    environment = tmp_path / "environment.parquet"
    frames = [(q.stem, f) for q in sequences for f in range(30)]
    pq.write_table(pa.table({"sequence": [q for q, _ in frames],
                             "frame": pa.array([f for _, f in frames], pa.int32()),
                             **{f"e{i}": np.zeros(len(frames), np.float32) for i in range(10)}}),
                   environment)
    db = tmp_path / "r.duckdb"
    build_database(db, sequences[0].parent, {"trials": out}, 5.0, DevkitSection(),
                   environment=environment)
    con = duckdb.connect(str(db), read_only=True)
    try:
        ends = dict(con.execute("SELECT trial, max(end_frame) FROM rte_frames WHERE "
                                "sequence = 'seq_a' GROUP BY trial").fetchall())
        rows = dict(con.execute("SELECT trial, count(*) FROM surrogate_rows GROUP BY trial")
                    .fetchall())
    finally:
        con.close()
    assert pruned and set(ends) == set(rows) == set(range(12))
    for i in pruned:  # the segments that ended before the trial stopped, no more
        last = len(read_trajectory(trajectory_path(out, "drift", "seq_a", i))) - 1
        assert ends[i] == last and 0 < rows[i] < rows[0]
    assert all(ends[i] == 29 for i in set(ends) - set(pruned))


def test_a_resumed_study_prunes_as_an_uninterrupted_one(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    """The curves of finished trials come back from their trajectories on resume."""
    s = settings(iterations=14, pruning=PRUNING)
    with pytest.raises(Interrupt):
        run_trials(sequences[:1], tmp_path / "k", s, seed=8, progress=False,
                   on_trial=interrupt_after(9), executor=pool)
    run_trials(sequences[:1], tmp_path / "k", s, seed=8, progress=False, executor=pool)
    run_trials(sequences[:1], tmp_path / "w", s, seed=8, progress=False, executor=pool)
    whole = table(tmp_path / "w")
    assert "pruned" in whole["status"][9:] and table(tmp_path / "k") == whole


def test_a_joint_study_prunes_across_sequences(sequences: list[Path], pool: Executor,
                                               tmp_path: Path) -> None:
    s = settings(iterations=12, pruning=PRUNING)
    (joint,) = run_trials(sequences, tmp_path, s, seed=5, joint=True, progress=False,
                          executor=pool)
    t = table(tmp_path, "__joint__")
    assert joint.pruned == t["status"].count("pruned") > 0
    for i, st in enumerate(t["status"]):
        ran = [trajectory_path(tmp_path, "drift", q.stem, i).is_file() for q in sequences]
        assert ran[0]  # every trial starts on the first sequence
        if st == "ok":
            assert all(ran)
    params = json.loads(t["params_json"][0])
    assert params == {"bias": 0.5, "gain": 1.0, "window": 3.0}
