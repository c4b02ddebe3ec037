"""One writer per trials folder, and a resume only of the same study (its fingerprint)."""

from __future__ import annotations

import json
import shutil
from concurrent.futures import Executor
from pathlib import Path

import helpers.tuning_adapters as tuning_adapters
import pytest
from click.testing import CliRunner
from helpers.tuning_settings import settings

from pipeline.errors import ConfigError
from pipeline.io_utils import exclusive_folder
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import read_study, trials_path
from stages.cli import main


def test_a_second_trials_run_on_the_same_folder_fails_in_one_line(
        sequences: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "out"
    params = tmp_path / "params.yaml"
    params.write_text(json.dumps({"base": {"seed": 1, "length_m": 5.0}, "trials": {
        "algorithm": "helpers.tuning_adapters:drift", "iterations": 2, "time_limit_s": None}}))
    with exclusive_folder(out):  # a trials run holding the folder (flock: per open file)
        res = CliRunner().invoke(main, ["trials", str(sequences[0]), "--out", str(out),
                                        "--params", str(params)])
    assert res.exit_code == 1
    assert res.output.strip().splitlines() == [
        f"adaptune: error: {out}: another adaptune trials is writing there (the folder is "
        "locked); wait for it to end or use another output folder"]
    assert not any(out.iterdir())
    res = CliRunner().invoke(main, ["trials", str(sequences[0]), "--out", str(out), "--params",
                                    str(params)])
    assert res.exit_code == 0, res.output  # the lock went with its holder


@pytest.mark.parametrize("change, named", [
    (dict(seed=8), "seed 8, stored 7"),
    (dict(length_m=6.0), "length_m 6.0, stored 5.0"),
    (dict(penalty_pct=50.0), "penalty_pct 50.0, stored 100.0"),
    (dict(jump_limit_m=2.0), "jump_limit_m 2.0, stored 5.0"),
    (dict(time_limit_s=None), "time_limit_s null, stored 20.0"),
    (dict(startup_trials=5), "startup_trials 5, stored 3"),
    (dict(workers=2), "told_lag 3, stored 1"),
    (dict(algorithm="helpers.tuning_adapters:failing", adapter_options={"mode": "raise"}),
     "adapter \"helpers.tuning_adapters:failing\", stored \"helpers.tuning_adapters:drift\""),
])
def test_a_resume_of_another_study_is_refused_naming_what_differs(
        sequences: list[Path], pool: Executor, tmp_path: Path, change: dict[str, object],
        named: str) -> None:
    base = dict(iterations=2)
    run_trials(sequences[:1], tmp_path, settings(**base), seed=7, progress=False, executor=pool)
    kw = {**base, **{k: v for k, v in change.items() if k != "seed"}}
    seed = int(change.get("seed", 7))  # type: ignore[call-overload]
    if "algorithm" in change:  # another adapter name writes elsewhere: put the table there
        src, dst = trials_path(tmp_path, "drift", "seq_a"), trials_path(tmp_path, "failing",
                                                                         "seq_a")
        dst.parent.mkdir(parents=True)
        shutil.copy(src, dst)
    with pytest.raises(ConfigError, match="holds a study with other settings") as err:
        run_trials(sequences[:1], tmp_path, settings(**kw), seed=seed, progress=False,
                   executor=pool)
    assert named in str(err.value) and "\n" not in str(err.value)


def test_a_changed_sequence_file_is_another_study(sequences: list[Path], pool: Executor,
                                                   tmp_path: Path) -> None:
    seq = tmp_path / "seq_a.mcap"
    shutil.copy(sequences[0], seq)
    run_trials([seq], tmp_path / "out", settings(iterations=2), seed=7, progress=False,
               executor=pool)
    (stored,) = read_study(trials_path(tmp_path / "out", "drift", "seq_a"))["sequences"]
    assert stored["name"] == "seq_a" and len(stored["sha256"]) == 64
    # more iterations: the same study, extended
    run_trials([seq], tmp_path / "out", settings(iterations=3), seed=7, progress=False,
               executor=pool)
    tuning_adapters.write_sequence(seq, seed=5)  # same name, other scans
    with pytest.raises(ConfigError, match=r"content of sequence seq_a changed \(sha256 "):
        run_trials([seq], tmp_path / "out", settings(iterations=3), seed=7, progress=False,
                   executor=pool)


def test_a_table_without_a_fingerprint_is_not_resumed(sequences: list[Path], pool: Executor,
                                                     tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    run_trials(sequences[:1], tmp_path, settings(iterations=2), seed=7, progress=False,
               executor=pool)
    path = trials_path(tmp_path, "drift", "seq_a")
    table = pq.read_table(path)
    meta = {k: v for k, v in table.schema.metadata.items() if k != b"adaptune.study"}
    pq.write_table(table.replace_schema_metadata(meta), path)
    with pytest.raises(ConfigError, match="without a study fingerprint"):
        run_trials(sequences[:1], tmp_path, settings(iterations=3), seed=7, progress=False,
                   executor=pool)
