"""A joint study that starts from what the per-sequence studies measured."""

from __future__ import annotations

import json
from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from conftest import settings
from tuning_adapters import SPACE

from pipeline.errors import ConfigError
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import JOINT, best_params, trials_path
from stages.cli import main


def test_the_joint_study_tries_the_per_sequence_bests_first(
        sequences: list[Path], pool: Executor, tmp_path: Path) -> None:
    s = settings(iterations=8)
    per = run_trials(sequences, tmp_path / "trials", s, seed=3, progress=False, executor=pool)
    first = best_params(tmp_path / "trials", "drift", SPACE)
    bests = [summary.best_params for summary in per]
    assert first == [p for i, p in enumerate(bests) if p not in bests[:i]]  # repeats dropped
    run_trials(sequences, tmp_path / "fixed", s, seed=3, joint=True, progress=False,
               executor=pool, warm_start=first)
    t = pq.read_table(trials_path(tmp_path / "fixed", "drift", JOINT)).to_pydict()
    assert [json.loads(p) for p in t["params_json"][1:1 + len(first)]] == first
    assert json.loads(t["params_json"][0]) == SPACE.defaults()  # the baseline stays trial 0
    # the starting points define the study: other ones are another study
    with pytest.raises(ConfigError, match="warm_start"):
        run_trials(sequences, tmp_path / "fixed", s, seed=3, joint=True, progress=False,
                   executor=pool, warm_start=[*first, {"bias": 0.0, "gain": 1.0, "window": 4.0}])


def test_warm_start_options(sequences: list[Path], tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({"base": {"seed": 1, "length_m": 5.0},
                                  "trials": {"algorithm": "tuning_adapters:drift"},
                                  "fixed": {"warm_start": True}}))
    run = ["trials", *map(str, sequences), "--out", str(tmp_path / "o"), "--params", str(params)]
    res = CliRunner().invoke(main, [*run, "--warm-start", str(tmp_path)])
    assert res.exit_code == 1 and "--warm-start goes with --joint" in res.output
    res = CliRunner().invoke(main, [*run, "--joint"])
    assert res.exit_code == 1 and "fixed.warm_start needs --warm-start DIR" in res.output
    res = CliRunner().invoke(main, [*run, "--joint", "--warm-start", str(tmp_path / "none")])
    assert res.exit_code == 1 and "no trials of 'drift'" in res.output
