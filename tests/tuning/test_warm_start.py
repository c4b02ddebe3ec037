"""A joint study that starts from what the per-sequence studies measured: the parameter sets
they predict best for all sequences together."""

from __future__ import annotations

import json
from concurrent.futures import Executor
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from helpers.tuning_adapters import SPACE
from helpers.tuning_settings import settings

from pipeline.errors import ConfigError
from pipeline.tuning.job import TrialResult
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import JOINT, trials_path, write_trials
from pipeline.tuning.warm_start import warm_start_params
from stages.cli import main


def study(out: Path, name: str, biases: np.ndarray, best: float) -> None:
    """A per-sequence study whose RTE is 1 + 10 (bias - best)^2 (gain, window at defaults);
    its last trial failed (the penalty)."""
    params = [{"bias": float(b), "gain": 1.0, "window": 3.0} for b in biases]
    results = [TrialResult(trial=i, status="ok", error="", objective=1 + 10 * (p["bias"] - best)
                           ** 2, wall_time_s=0.1, seed=i, params=p)
               for i, p in enumerate(params)]
    results[-1] = TrialResult(trial=len(params) - 1, status="failed", error="x",
                              objective=100.0, wall_time_s=0.1, seed=0, params=params[-1])
    path = trials_path(out, "drift", name)
    path.parent.mkdir(parents=True)
    write_trials(path, SPACE, results, {"space": SPACE.to_json()})


def test_the_start_is_the_predicted_joint_best_not_each_sequences_best(tmp_path: Path) -> None:
    study(tmp_path, "seq_a", np.linspace(-1.0, 1.0, 21), best=-0.6)  # its best: bias -0.6
    study(tmp_path, "seq_b", np.linspace(-0.95, 0.95, 20), best=0.6)  # its best: bias 0.6
    first = warm_start_params(tmp_path, "drift", SPACE, 3)
    assert len(first) == 3
    # both sequences together are best at bias 0 (1 + 3.6 each); -0.6 or 0.6: 1 + 7.2 on avg.
    assert [abs(p["bias"]) <= 0.15 for p in first] == [True] * 3
    assert abs(first[0]["bias"]) < 0.051 and (first[0]["gain"], first[0]["window"]) == (1, 3)
    assert len(warm_start_params(tmp_path, "drift", SPACE, 100)) == 41  # every set measured


def test_the_joint_study_tries_the_predicted_sets_first(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = settings(iterations=8)
    run_trials(sequences, tmp_path / "trials", s, seed=3, progress=False, executor=pool)
    first = warm_start_params(tmp_path / "trials", "drift", SPACE, 2)
    run_trials(sequences, tmp_path / "fixed", s, seed=3, joint=True, progress=False,
               executor=pool, warm_start=first)
    t = pq.read_table(trials_path(tmp_path / "fixed", "drift", JOINT)).to_pydict()
    assert [json.loads(p) for p in t["params_json"][1:3]] == first
    assert json.loads(t["params_json"][0]) == SPACE.defaults()  # the baseline stays trial 0
    # the starting points define the study: other ones are another study
    with pytest.raises(ConfigError, match="warm_start"):
        run_trials(sequences, tmp_path / "fixed", s, seed=3, joint=True, progress=False,
                   executor=pool, warm_start=[*first, {"bias": 0.0, "gain": 1.0, "window": 4.0}])


def test_warm_start_options(sequences: list[Path], tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({"base": {"seed": 1, "length_m": 5.0},
                                  "trials": {"algorithm": "helpers.tuning_adapters:drift"},
                                  "fixed": {"warm_start": 4}}))
    run = ["trials", *map(str, sequences), "--out", str(tmp_path / "o"), "--params", str(params)]
    res = CliRunner().invoke(main, [*run, "--warm-start", str(tmp_path)])
    assert res.exit_code == 1 and "--warm-start goes with --joint" in res.output
    res = CliRunner().invoke(main, [*run, "--joint"])
    assert res.exit_code == 1 and "fixed.warm_start needs --warm-start DIR" in res.output
    res = CliRunner().invoke(main, [*run, "--joint", "--warm-start", str(tmp_path / "none")])
    assert res.exit_code == 1 and "no trials of 'drift'" in res.output
    params.write_text(json.dumps({"fixed": {"warm_start": -1}}))
    res = CliRunner().invoke(main, [*run, "--joint", "--warm-start", str(tmp_path)])
    assert res.exit_code == 1 and "warm_start" in res.output


def test_the_joint_study_has_its_own_pruner(sequences: list[Path], tmp_path: Path) -> None:
    """fixed.pruning replaces trials.pruning for the joint study only: the per-sequence
    studies run whole (their rows train the surrogate), the joint one prunes."""
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({
        "base": {"seed": 1, "length_m": 5.0},
        "trials": {"algorithm": "helpers.tuning_adapters:drift", "iterations": 12, "workers": 1,
                   "startup_trials": 3, "pruning": {"percentile": None}},
        "fixed": {"iterations": 12, "warm_start": 0,  # not the defaults: 64 and 4
                  "pruning": {"percentile": 10.0, "checkpoints": 5, "warmup": 0.2,
                              "min_trials": 3}}}))

    def statuses(*extra: str) -> set[str]:
        out = tmp_path / ("fixed" if extra else "trials")
        res = CliRunner().invoke(main, ["trials", *map(str, sequences), "--out", str(out),
                                        "--params", str(params), "--json", *extra])
        assert res.exit_code == 0, res.output
        tables = sorted(out.glob("trials/algorithm=drift/sequence=*/trials.parquet"))
        return {st for t in tables for st in pq.read_table(t).column("status").to_pylist()}

    assert statuses() == {"ok"}
    assert statuses("--joint") == {"ok", "pruned"}
