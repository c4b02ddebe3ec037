"""The SMBO runner: determinism, failing adapters, kill + resume, Dask, the joint objective."""

from __future__ import annotations

from concurrent.futures import Executor
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers.tuning_settings import Interrupt, interrupt_after, settings

from pipeline.metrics.rte import mean_rte_pct
from pipeline.sequence import SequenceReader
from pipeline.trajectory import read_trajectory
from pipeline.tuning.job import trajectory_path
from pipeline.tuning.section import TrialsSection
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import trials_path
from schemas.arrow import trials_schema


def table(out: Path, algorithm: str, sequence: str) -> dict[str, list]:
    t = pq.read_table(trials_path(out, algorithm, sequence))
    assert t.schema.names == trials_schema(["bias", "gain", "window"]).names
    return t.to_pydict()


def without_time(d: dict[str, list]) -> dict[str, list]:
    return {k: v for k, v in d.items() if k != "wall_time_s"}


def test_serial_runs_with_one_seed_are_identical(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    s = settings()
    runs = [
        run_trials(sequences[:1], tmp_path / f"r{i}", s, seed=seed, progress=False, executor=pool)
        for i, seed in enumerate((7, 7, 8))
    ]
    a, b, c = (table(tmp_path / f"r{i}", "drift", "seq_a") for i in range(3))
    assert a["trial"] == list(range(6)) and set(a["status"]) == {"ok"}
    assert without_time(a) == without_time(b)
    assert a["p_bias"][1:] != c["p_bias"][1:]
    assert a["params_json"][0] == '{"bias": 0.5, "gain": 1.0, "window": 3.0}'  # trial 0 = baseline
    assert a["p_bias"][0] == c["p_bias"][0] == 0.5
    assert runs[0][0].trials == 6 and runs[0][0].failed == 0
    assert runs[0][0].best_objective == min(a["objective"])
    for tid in range(6):
        assert trajectory_path(tmp_path / "r0", "drift", "seq_a", tid).is_file()


def test_parallel_runs_with_one_seed_are_identical(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    """Two trials in flight finish in varying order; the proposals do not depend on it."""
    s = settings(algorithm="helpers.tuning_adapters:sleepy", workers=2, iterations=12,
                 startup_trials=3)
    for i in range(3):
        run_trials(sequences[:1], tmp_path / f"p{i}", s, seed=5, progress=False, executor=pool)
    a, b, c = (table(tmp_path / f"p{i}", "sleepy", "seq_a") for i in range(3))
    assert a["trial"] == list(range(12)) and set(a["status"]) == {"ok"}
    assert without_time(a) == without_time(b) == without_time(c)
    assert len(set(a["p_bias"])) == 12


def test_told_lag_keeps_serial_runs_serial() -> None:
    from pipeline.tuning.smbo import told_lag

    assert told_lag(1) == 1 and told_lag(2) == 3 and told_lag(8) == 15


@pytest.mark.parametrize(
    "mode, message",
    [
        ("raise", "RuntimeError: odometry diverged on purpose"),
        ("nan", "non-finite pose"),
        ("lose", "poses for 30 frames"),
        ("jump", "implausible jump"),
    ],
)
def test_failing_adapters_give_failed_trials(
    sequences: list[Path], pool: Executor, tmp_path: Path, mode: str, message: str
) -> None:
    s = settings(
        algorithm="helpers.tuning_adapters:failing",
        adapter_options={"mode": mode, "threshold": 0.0},
        iterations=8,
        penalty_pct=77.0,
    )
    (summary,) = run_trials(sequences[:1], tmp_path, s, seed=1, progress=False, executor=pool)
    t = table(tmp_path, "failing", "seq_a")
    failed = [i for i, st in enumerate(t["status"]) if st == "failed"]
    assert 0 in failed  # the baseline has bias 0.5 > 0
    assert 0 < len(failed) < 8 and summary.failed == len(failed) and summary.trials == 8
    for i in range(8):
        bad = t["p_bias"][i] > 0.0
        assert (t["status"][i] == "failed") == bad
        assert (message in t["error"][i]) == bad
        assert (t["objective"][i] == 77.0) == bad
        assert trajectory_path(tmp_path, "failing", "seq_a", i).is_file() != bad


def test_hanging_adapter_is_killed_at_the_time_limit(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    s = settings(
        algorithm="helpers.tuning_adapters:failing",
        adapter_options={"mode": "hang", "threshold": 0.0},
        iterations=3,
        time_limit_s=5.0,  # the trial that does not hang ends well within it under load too
        workers=2,
    )
    (summary,) = run_trials(sequences[:1], tmp_path, s, seed=4, progress=False, executor=pool)
    t = table(tmp_path, "failing", "seq_a")
    assert t["trial"] == [0, 1, 2]
    assert t["status"][0] == "failed" and "time limit of 5 s exceeded" in t["error"][0]
    assert summary.failed == sum(b > 0 for b in t["p_bias"])


def test_killed_run_resumes_to_exactly_n_trials(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    s = settings(iterations=7)
    with pytest.raises(Interrupt):
        run_trials(
            sequences[:1],
            tmp_path / "killed",
            s,
            seed=5,
            progress=False,
            on_trial=interrupt_after(3),
            executor=pool,
        )
    assert table(tmp_path / "killed", "drift", "seq_a")["trial"] == [0, 1, 2]
    seen: list[int] = []
    (summary,) = run_trials(
        sequences[:1],
        tmp_path / "killed",
        s,
        seed=5,
        progress=False,
        on_trial=lambda st, r: seen.append(r.trial),
        executor=pool,
    )
    assert seen == [3, 4, 5, 6] and summary.ran == 4 and summary.trials == 7
    resumed = table(tmp_path / "killed", "drift", "seq_a")
    assert resumed["trial"] == list(range(7))
    run_trials(sequences[:1], tmp_path / "whole", s, seed=5, progress=False, executor=pool)
    assert without_time(resumed) == without_time(table(tmp_path / "whole", "drift", "seq_a"))
    # a finished study runs nothing more
    (again,) = run_trials(
        sequences[:1], tmp_path / "killed", s, seed=5, progress=False, executor=pool
    )
    assert again.ran == 0 and again.trials == 7


def test_parallel_trials_in_flight(sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    (summary,) = run_trials(
        sequences[:1],
        tmp_path,
        settings(iterations=8, workers=2),
        seed=2,
        progress=False,
        executor=pool,
    )
    t = table(tmp_path, "drift", "seq_a")
    assert t["trial"] == list(range(8)) and set(t["status"]) == {"ok"}
    assert len(set(t["params_json"])) == 8 and summary.trials == 8


def test_dask_local_cluster_gives_the_same_number_of_valid_trials(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    s = settings(
        algorithm="helpers.tuning_adapters:failing",
        adapter_options={"mode": "raise", "threshold": 0.3},
        iterations=6,
        workers=2,
    )
    run_trials(
        sequences[:1],
        tmp_path / "pool",
        s.model_copy(update={"workers": 1}),
        seed=3,
        progress=False,
        executor=pool,
    )
    (summary,) = run_trials(
        sequences[:1],
        tmp_path / "dask",
        s.model_copy(update={"dask": "local"}),
        seed=3,
        progress=False,
    )
    ref = table(tmp_path / "pool", "failing", "seq_a")
    got = table(tmp_path / "dask", "failing", "seq_a")
    assert got["trial"] == list(range(6)) and summary.trials == 6
    valid = [o for o, st in zip(got["objective"], got["status"], strict=True) if st == "ok"]
    assert len(valid) == sum(b <= 0.3 for b in got["p_bias"]) and all(np.isfinite(valid))
    # trial 0 (the baseline, bias 0.5) fails in both; TPE start-up proposals differ only by seed
    assert got["status"][0] == ref["status"][0] == "failed"
    assert got["p_bias"][:3] == ref["p_bias"][:3]  # baseline + random start-up: same seeds


def test_joint_objective_is_the_mean_over_sequences(
    sequences: list[Path], pool: Executor, tmp_path: Path
) -> None:
    s = settings(iterations=3)
    (joint,) = run_trials(
        sequences, tmp_path / "fixed", s, seed=9, joint=True, progress=False, executor=pool
    )
    assert joint.sequence == "__joint__"
    t = table(tmp_path / "fixed", "drift", "__joint__")
    for tid, objective in zip(t["trial"], t["objective"], strict=True):
        per_seq = []
        for seq in sequences:
            with SequenceReader(seq) as r:
                gt = r.ground_truth()
            est = read_trajectory(trajectory_path(tmp_path / "fixed", "drift", seq.stem, tid))
            per_seq.append(mean_rte_pct(gt, est.T_world_lidar, 5.0))
        assert per_seq[0] != pytest.approx(per_seq[1])
        assert objective == pytest.approx(np.mean(per_seq), rel=1e-12)
    # the baseline of the joint study is the mean of the per-sequence baselines
    run_trials(
        sequences,
        tmp_path / "per",
        s.model_copy(update={"iterations": 1}),
        seed=9,
        progress=False,
        executor=pool,
    )
    base = [table(tmp_path / "per", "drift", seq.stem)["objective"][0] for seq in sequences]
    assert t["objective"][0] == pytest.approx(np.mean(base), rel=1e-12)


def test_settings_rules() -> None:
    from pipeline.config import validate_section
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError, match=r"trials\.iterations"):
        validate_section(TrialsSection, "trials", {"iterations": 0})
    with pytest.raises(ConfigError, match="dask must be 'local' or a scheduler address"):
        validate_section(TrialsSection, "trials", {"dask": "somewhere"})
