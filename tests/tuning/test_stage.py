"""``adaptune trials`` through the CLI, and the tuner on the real ndt adapter."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from pipeline.tuning.job import trajectory_path
from pipeline.tuning.table import trials_path
from stages.cli import main


def params_file(tmp_path: Path, fixed: dict[str, object] | None = None,
                **trials: object) -> Path:
    p = tmp_path / "params.yaml"
    section = dict(
        algorithm="helpers.tuning_adapters:drift",
        iterations=3,
        time_limit_s=20.0,
        startup_trials=2,
    )
    section.update(trials)
    p.write_text(json.dumps({"base": {"seed": 3, "length_m": 5.0}, "trials": section,
                             **({"fixed": fixed} if fixed is not None else {})}))
    return p


def test_dvc_form_reads_the_split_of_index_json(sequences: list[Path], tmp_path: Path) -> None:
    folder = sequences[0].parent
    (folder / "index.json").write_text(json.dumps({"train": ["seq_a", "seq_b"], "validation": []}))
    out = tmp_path / "results" / "fixed"
    res = CliRunner().invoke(
        main,
        [
            "trials",
            "--sequences",
            str(folder),
            "--joint",
            "--out",
            str(out),
            "--params",
            str(params_file(tmp_path, fixed={"warm_start": 0})),  # the default 4 needs trials
            "--iterations",
            "2",
        ],
    )
    assert res.exit_code == 0, res.output
    t = pq.read_table(trials_path(out, "drift", "__joint__")).to_pydict()
    assert t["trial"] == [0, 1] and t["seed"][0] != t["seed"][1]
    assert trajectory_path(out, "drift", "seq_b", 1).is_file()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--length-m", "500"], "not longer than length_m=500.0"),
        (["--algorithm", "nope"], "unknown odometry algorithm 'nope'"),
        (["--iterations", "0"], "trials.iterations: must be an integer in [1, 1000000]"),
        (["--dask", "nowhere"], "dask must be 'local' or a scheduler address"),
    ],
)
def test_bad_input_exits_1_without_output(
    sequences: list[Path], tmp_path: Path, args: list[str], message: str
) -> None:
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main,
        [
            "trials",
            str(sequences[0]),
            "--out",
            str(out),
            "--params",
            str(params_file(tmp_path)),
            *args,
        ],
    )
    assert res.exit_code == 1
    assert "adaptune: error: " in res.output and message in res.output, res.output
    assert not out.exists()


def test_an_unknown_rung_unit_is_one_line(sequences: list[Path], tmp_path: Path) -> None:
    """``trials.halving.unit`` names what it accepts; nothing is written."""
    out = tmp_path / "out"
    params = params_file(tmp_path, fidelity="halving", halving={"unit": "window"})
    res = CliRunner().invoke(main, ["trials", str(sequences[0]), "--out", str(out),
                                    "--params", str(params)])
    assert res.exit_code == 1 and res.output.splitlines() == [
        "adaptune: error: trials.halving.unit: Input should be 'prefix' or 'sequence', got "
        "'window'"], res.output
    assert not out.exists()


def test_missing_split_is_one_line(sequences: list[Path], tmp_path: Path) -> None:
    folder = tmp_path / "seqs"
    folder.mkdir()
    (folder / "index.json").write_text(json.dumps({"train": ["gone"]}))
    res = CliRunner().invoke(
        main,
        [
            "trials",
            "--sequences",
            str(folder),
            "--out",
            str(tmp_path / "o"),
            "--params",
            str(params_file(tmp_path)),
        ],
    )
    assert (
        res.exit_code == 1 and "split 'train' lists gone.mcap, which does not exist" in res.output
    )


def test_ndt_trials_on_a_ray_cast_sequence(tmp_path: Path) -> None:
    from helpers.odometry_data import write_synthetic_sequence

    seq = write_synthetic_sequence(
        tmp_path / "yard.mcap", n_frames=12, step_m=0.8, azimuth_steps=450
    )
    out = tmp_path / "trials"
    res = CliRunner().invoke(
        main,
        [
            "trials",
            str(seq),
            "--out",
            str(out),
            "--algorithm",
            "ndt",
            "--iterations",
            "5",
            "--params",
            str(params_file(tmp_path, algorithm="ndt", time_limit_s=60.0)),
        ],
    )
    assert res.exit_code == 0, res.output
    t = pq.read_table(trials_path(out, "ndt", "yard")).to_pydict()
    assert t["trial"] == list(range(5))
    assert t["p_resolution"][0] == 4.0 and t["p_keyframe_interval"][0] == 4.0
    ok = [o for o, s in zip(t["objective"], t["status"], strict=True) if s == "ok"]
    assert t["status"][0] == "ok" and t["objective"][0] < 10.0  # the baseline tracks the yard
    assert min(ok) <= t["objective"][0]
    assert all(
        trajectory_path(out, "ndt", "yard", i).is_file() == (s == "ok")
        for i, s in enumerate(t["status"])
    )


def test_first_try_without_params_file_and_json_summary(
    sequences: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No params.yaml in the working folder: every section at its defaults (L = 25 m fits the
    29 m sequence); --json puts the study summaries on stdout, nothing on stderr."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    args = ["trials", str(sequences[0]), "--out", str(out), "--algorithm",
            "helpers.tuning_adapters:drift", "--iterations", "2"]
    res = CliRunner().invoke(main, [*args, "--json"])
    assert res.exit_code == 0, res.output
    assert res.stderr == ""
    (study,) = json.loads(res.stdout)
    assert (study["algorithm"], study["sequence"], study["trials"]) == ("drift", "seq_a", 2)
    res = CliRunner().invoke(main, args)  # resumed: nothing to run; the summary on stderr
    assert res.exit_code == 0 and res.stdout == ""
    assert res.stderr.splitlines() == [
        f"drift seq_a: 2 trials (0 run now), {study['failed']} failed, {study['pruned']} "
        f"pruned, best objective {study['best_objective']:.4g} % (trial {study['best_trial']})"]
