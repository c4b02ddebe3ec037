"""`adaptune export --format optuna`: trials folders as an Optuna storage (issue 57.3), read back
with ``optuna.load_study`` and checked against the trials tables; optuna-dashboard's own API
serves it."""

from __future__ import annotations

import json
from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from helpers.tuning_settings import settings

from pipeline.tuning.job import TrialResult
from pipeline.tuning.layout import trajectory_path
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import read_study, read_trials, trials_path, write_trials
from stages.cli import main

optuna = pytest.importorskip("optuna")

ALGORITHM = "failing"
STATE = {"ok": "COMPLETE", "pruned": "PRUNED", "failed": "FAIL"}


@pytest.fixture(scope="module")
def folders(sequences: list[Path], pool: Executor, tmp_path_factory: pytest.TempPathFactory
            ) -> tuple[Path, Path]:
    """A per-sequence study with ok, pruned, failed and one lost trial (results/trials) and a
    joint study of both sequences (results/fixed)."""
    root = tmp_path_factory.mktemp("optuna")
    s = settings(algorithm=f"helpers.tuning_adapters:{ALGORITHM}", iterations=14,
                 adapter_options={"mode": "raise", "threshold": 0.3}, penalty_pct=77.0,
                 pruning={"percentile": 50.0, "checkpoints": 5, "warmup": 0.2, "min_trials": 3})
    trials, fixed = root / "trials", root / "fixed"
    run_trials(sequences[:1], trials, s, seed=5, progress=False, executor=pool)
    run_trials(sequences, fixed, settings(algorithm=f"helpers.tuning_adapters:{ALGORITHM}",
                                          adapter_options={"mode": "raise", "threshold": 0.6},
                                          iterations=4), seed=2, joint=True, progress=False,
               executor=pool)
    # a lost trial, as a study that lost one beyond its retries stores it (the real writer)
    table = trials_path(trials, ALGORITHM, "seq_a")
    study = read_study(table)
    from pipeline.odometry.base import ParameterSpace

    space = ParameterSpace.from_json(study["space"])  # type: ignore[index]
    done = read_trials(table, space)
    lost = TrialResult(trial=len(done), status="lost", error="trial process killed",
                       objective=float("nan"), wall_time_s=0.5, seed=99,
                       params=space.defaults())
    write_trials(table, space, [*done, lost], study)  # type: ignore[arg-type]
    return trials, fixed


def rows(folder: Path, sequence: str) -> list[dict]:
    return pq.read_table(trials_path(folder, ALGORITHM, sequence)).to_pylist()


def test_studies_match_the_trials_tables(folders: tuple[Path, Path], tmp_path: Path) -> None:
    """Counts, values, states, parameters, distributions and frames of every trial, read back
    with optuna.load_study; the lost trial is left out and counted on stderr."""
    trials, fixed = folders
    out = tmp_path / "studies.db"
    result = CliRunner().invoke(main, ["export", str(trials), str(fixed), "--format", "optuna",
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "2 Optuna studies" in result.stderr and "1 lost trials left out" in result.stderr
    storage = f"sqlite:///{out}"
    names = sorted(s.study_name for s in optuna.get_all_study_summaries(storage))
    assert names == ["fixed/failing/__joint__", "trials/failing/seq_a"]
    for name, folder, sequence, n_seq in (("trials/failing/seq_a", trials, "seq_a", 1),
                                          ("fixed/failing/__joint__", fixed, "__joint__", 2)):
        table = rows(folder, sequence)
        kept = [r for r in table if r["status"] != "lost"]
        study = optuna.load_study(study_name=name, storage=storage)
        got = study.get_trials(deepcopy=False)
        assert len(got) == len(kept) == len(table) - (sequence == "seq_a")
        assert study.direction == optuna.study.StudyDirection.MINIMIZE
        for row, trial in zip(kept, got, strict=True):
            assert trial.user_attrs["trial"] == row["trial"]
            assert "wall_time_s" not in trial.user_attrs  # a trials table keeps no time
            assert trial.state.name == STATE[row["status"]]
            if row["status"] == "failed":
                assert trial.value is None
                assert trial.user_attrs["penalty_pct"] == row["objective"] > 0
                assert "error" in trial.user_attrs and trial.user_attrs["frames"] == 0
            else:
                assert trial.value == row["objective"]
            params = json.loads(row["params_json"])
            assert trial.params == pytest.approx(params)
            assert isinstance(trial.params["window"], int)
            dist = trial.distributions
            assert dist["gain"] == optuna.distributions.FloatDistribution(0.25, 4.0, log=True)
            assert dist["bias"] == optuna.distributions.FloatDistribution(-1.0, 1.0)
            assert dist["window"] == optuna.distributions.IntDistribution(1, 6)
            frames = sum(len(pq.read_table(p)) for p in (
                trajectory_path(folder, ALGORITHM, s, row["trial"])
                for s in (["seq_a", "seq_b"] if n_seq == 2 else ["seq_a"])) if p.is_file())
            assert trial.user_attrs["frames"] == frames
            if row["status"] == "pruned":
                assert trial.intermediate_values == {frames: row["objective"]}
                assert 0 < frames < 30
            if row["status"] == "ok":
                assert frames == 30 * n_seq
    seq_a = [r["status"] for r in rows(trials, "seq_a")]
    assert {"ok", "pruned", "failed", "lost"} <= set(seq_a)  # every state was exercised


def test_optuna_dashboard_serves_it(folders: tuple[Path, Path], tmp_path: Path) -> None:
    """optuna-dashboard's WSGI app lists the exported study and its trials."""
    dashboard = pytest.importorskip("optuna_dashboard")
    from wsgiref.util import setup_testing_defaults

    trials, _ = folders
    out = tmp_path / "trials.db"
    result = CliRunner().invoke(main, ["export", str(trials), "--format", "optuna",
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    app = dashboard.wsgi(f"sqlite:///{out}")

    def get(path: str) -> dict:
        env: dict = {"PATH_INFO": path}
        setup_testing_defaults(env)
        status: list[str] = []
        body = b"".join(app(env, lambda s, h, *a: status.append(s)))
        assert status[0].startswith("200"), (path, status)
        return json.loads(body)

    (study,) = get("/api/studies")["study_summaries"]
    assert study["study_name"] == "trials/failing/seq_a"
    detail = get(f"/api/studies/{study['study_id']}")
    assert len(detail["trials"]) == len(rows(trials, "seq_a")) - 1


def test_refusals_are_one_line(folders: tuple[Path, Path], tmp_path: Path) -> None:
    trials, _ = folders
    for args, message in (
            ([str(tmp_path), "--format", "optuna"], "no trials table"),
            ([str(trials), "--format", "optuna", "--anchor", "identity"],
             "--anchor belong to a trajectory export"),
            ([str(trials), str(trials), "--format", "optuna"], "export the two folders"),
            ([str(trials), "--format", "kitti"], "a trials folder exports with --format optuna"),
            ([str(trials), str(trials), "--format", "tum"], "one trajectory, got 2")):
        result = CliRunner().invoke(main, ["export", *args, "--out", str(tmp_path / "o.db")])
        assert result.exit_code == 1 and message in result.stderr, (args, result.output)
        assert not (tmp_path / "o.db").exists()
