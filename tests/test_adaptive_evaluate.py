"""The `ingest-set`, `adaptive` and `evaluate` stages: params sections and bad input.

The happy path of all three runs through DVC in tests/test_pipeline_dvc.py.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from pipeline.config import load_section
from pipeline.errors import ConfigError
from pipeline.tuning.job import TrialResult
from pipeline.tuning.section import FixedSection
from stages.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_every_section_of_the_repository_params_validates() -> None:
    from pipeline.config import SECTIONS, section_model

    params = yaml.safe_load((REPO / "params.yaml").read_text())
    assert set(params) == set(SECTIONS)
    for name in SECTIONS:
        load_section(REPO / "params.yaml", name, section_model(name))
    # one L for trials, rte, evaluate and generalize: base.length_m, no copy in their sections
    assert not any("length_m" in params[s] for s in ("trials", "evaluate", "generalize"))


def _params(tmp_path: Path, **sections: dict) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(sections))
    return path


def _invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.output


def test_ingest_set_refuses_a_data_set_without_train_sequences(tmp_path: Path) -> None:
    params = _params(tmp_path, data={"sources": [
        {"kind": "kitti", "path": str(tmp_path), "sequences": ["04"], "split": "validation"}]})
    code, out = _invoke("ingest-set", "--params", str(params), "--out", str(tmp_path / "k"))
    assert code == 1
    assert out.strip().splitlines() == [
        "adaptune: error: data.sources: no recording in split 'train' (the one tuned on), got "
        "splits ['validation']"]
    assert not (tmp_path / "k" / "index.json").exists()


def test_an_ingest_section_says_where_its_settings_went(tmp_path: Path) -> None:
    params = _params(tmp_path, ingest={"kitti_root": str(tmp_path), "train": ["04"]})
    code, out = _invoke("ingest-set", "--params", str(params), "--out", str(tmp_path / "k"))
    assert code == 1 and out.count("\n") == 1
    assert "unknown params section 'ingest'" in out and "a kitti source of the data section" in out


def test_ingest_set_without_sources_writes_an_empty_index(tmp_path: Path) -> None:
    params = _params(tmp_path, data={})
    code, _ = _invoke("ingest-set", "--params", str(params), "--out", str(tmp_path / "k"))
    assert code == 0
    assert json.loads((tmp_path / "k" / "index.json").read_text()) == {
        "train": [], "validation": []}


def test_fixed_section_is_validated(tmp_path: Path) -> None:
    """(That --joint takes fixed.iterations over trials.iterations: tests/test_pipeline_dvc.py.)"""
    rule = r"fixed\.iterations: must be an integer in \[1, 1000000\] \(MAX_ITERATIONS\).*got 0"
    with pytest.raises(ConfigError, match=rule):
        load_section(_params(tmp_path, fixed={"iterations": 0}), "fixed", FixedSection)


@pytest.mark.parametrize(("section", "model", "value", "rule"), [
    ("evaluate", "EvaluateSection", {"replicas": -1},
     r"evaluate\.replicas: Input should be greater than or equal to 0, got -1"),
    ("evaluate", "EvaluateSection", {"replica_scale": 0.5},
     r"evaluate\.replica_scale: Input should be less than or equal to 0\.1, got 0\.5"),
    ("generalize", "GeneralizeSection", {"replica_scale": 0},
     r"generalize\.replica_scale: Input should be greater than 0, got 0"),
])
def test_replica_settings_are_validated(tmp_path: Path, section: str, model: str,
                                        value: dict, rule: str) -> None:
    from pipeline.config import section_model

    with pytest.raises(ConfigError, match=rule):
        load_section(_params(tmp_path, **{section: value}), section, section_model(section))
    assert model == section_model(section).__name__


@pytest.fixture(scope="module")
def validation_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """data/sequences with one short composite validation sequence (longer than L = 25 m:
    evaluate refuses a sequence it cannot score)."""
    from pipeline.sim.simulate import SimSpec, simulate_sequence

    folder = tmp_path_factory.mktemp("sequences")
    simulate_sequence(SimSpec("composite", 3, 48), folder / "composite_0.mcap", name="composite_0")
    (folder / "index.json").write_text(json.dumps({"train": [], "validation": ["composite_0"]}))
    return folder


def _joint_table(out: Path, algorithm: str = "ndt", status: str = "ok") -> Path:
    from pipeline.odometry import get_adapter
    from pipeline.tuning.table import JOINT, trials_path, write_trials

    space = get_adapter(algorithm).space
    result = TrialResult(0, status, "" if status == "ok" else "boom", 1.5, 1.0, 7,
                         space.defaults())
    write_trials(trials_path(out, algorithm, JOINT), space, [result], {"space": space.to_json()})
    return out


def _evaluate_args(tmp_path: Path, sequences: Path, fixed: Path, adaptive: Path) -> list[str]:
    return ["evaluate", "--params", str(REPO / "params.yaml"), "--sequences", str(sequences),
            "--trials", str(tmp_path / "trials"), "--fixed", str(fixed), "--adaptive",
            str(adaptive), "--out", str(tmp_path / "ev"), "--metrics", str(tmp_path / "m.json"),
            "--record", str(tmp_path / "r.json"), "--plots", str(tmp_path / "plots"),
            "--report", str(tmp_path / "report")]


def _evaluate(tmp_path: Path, sequences: Path, fixed: Path, adaptive: Path) -> tuple[int, str]:
    return _invoke(*_evaluate_args(tmp_path, sequences, fixed, adaptive))


def test_evaluate_without_the_fixed_stage_is_one_line(tmp_path: Path,
                                                      validation_set: Path) -> None:
    code, out = _evaluate(tmp_path, validation_set, tmp_path / "nofixed", tmp_path / "a")
    assert code == 1 and out.count("\n") == 1
    assert "nofixed: no such trials directory" in out
    assert not (tmp_path / "m.json").exists()


def test_evaluate_without_a_successful_joint_trial(tmp_path: Path, validation_set: Path) -> None:
    fixed = _joint_table(tmp_path / "fixed", status="failed")
    code, out = _evaluate(tmp_path, validation_set, fixed, tmp_path / "a")
    assert code == 1 and "no successful joint trial" in out


def test_trials_summary_counts_pruned_trials_apart_from_failed(tmp_path: Path) -> None:
    from pipeline.odometry import get_adapter
    from pipeline.report.metrics import trials_summary
    from pipeline.tuning.table import trials_path, write_trials

    space = get_adapter("ndt").space
    results = [TrialResult(i, status, "" if status == "ok" else "x", 1.5, 1.0, 7,
                           space.defaults())
               for i, status in enumerate(["ok", "pruned", "pruned", "failed", "lost"])]
    write_trials(trials_path(tmp_path, "ndt", "cave_0"), space, results,
                 {"space": space.to_json()})
    summary = trials_summary({"trials": tmp_path})["trials"]
    counts = tuple(summary[k] for k in ("trials", "failed", "pruned", "lost"))
    assert counts == (5, 1, 2, 1)


def test_evaluate_refuses_an_adaptive_run_of_another_algorithm(tmp_path: Path,
                                                               validation_set: Path) -> None:
    fixed = _joint_table(tmp_path / "fixed")
    run = tmp_path / "adaptive" / "composite_0"
    run.mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"algorithm": "gicp", "wall_time_s": 1.0}))
    code, out = _evaluate(tmp_path, validation_set, fixed, tmp_path / "adaptive")
    assert code == 1
    assert "adaptive run of 'gicp', the fixed parameters are for 'ndt'" in out
    assert not (tmp_path / "m.json").exists()


def test_evaluate_without_the_adaptive_stage(tmp_path: Path, validation_set: Path) -> None:
    fixed = _joint_table(tmp_path / "fixed")
    code, out = _evaluate(tmp_path, validation_set, fixed, tmp_path / "adaptive")
    assert code == 1 and "no adaptive run (run the `adaptive` stage)" in out


def test_adaptive_refuses_a_missing_or_tampered_model(tmp_path: Path,
                                                      validation_set: Path) -> None:
    args = ["adaptive", "--params", str(REPO / "params.yaml"), "--sequences",
            str(validation_set), "--out", str(tmp_path / "out")]
    code, out = _invoke(*args, "--model", str(tmp_path / "model"))
    assert code == 1 and "not a model artifact (no manifest.json)" in out
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "manifest.json").write_text("{not json")
    code, out = _invoke(*args, "--model", str(tmp_path / "model"))
    assert code == 1 and "damaged manifest" in out
    assert not (tmp_path / "out").exists()


def test_adaptive_and_evaluate_give_the_same_results_for_any_workers(
        tmp_path: Path, kitti_root: Path) -> None:
    """Sequences run in worker processes (evaluate.workers) give the outputs of one process:
    the same schedules and trajectories, the same figures in the same order."""
    import pyarrow.parquet as pq
    from helpers.models import build_model

    from pipeline.adaptive import run_adaptive
    from pipeline.evaluate.runs import evaluate
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.report.metrics import metrics
    from pipeline.sim.simulate import SimSpec, simulate_sequence

    model = build_model(tmp_path / "model", kitti_root)
    paths = []
    for name, seed, segments in (("composite_0", 3, ("cave", "street")),
                                 ("composite_1", 5, ("street", "open"))):
        paths.append(tmp_path / f"{name}.mcap")
        simulate_sequence(SimSpec("composite", seed, 40, segments=segments), paths[-1], name=name)
    fixed = _joint_table(tmp_path / "fixed")
    figures = []
    for workers in (1, 2):
        runs = run_adaptive(model, paths, tmp_path / f"a{workers}", workers=workers)
        assert [r.sequence for r in runs] == ["composite_0", "composite_1"]
        ev = evaluate(paths, "ndt", {"resolution": 2.0, "keyframe_interval": 6.0},
                      tmp_path / f"a{workers}", tmp_path / f"ev{workers}",
                      EvaluateSection(workers=workers, length_m=10.0),  # the worlds: ~21 m
                      fixed_dir=fixed)
        m = metrics(ev, {})
        for seq in m["sequences"].values():
            seq.pop("wall_time_s")
        figures.append(json.dumps(m, sort_keys=True))
    assert figures[0] == figures[1]
    for name in ("composite_0", "composite_1"):
        for table in ("schedule.parquet", "trajectory.parquet"):
            one, two = (pq.read_table(tmp_path / f"a{w}" / name / table) for w in (1, 2))
            assert one.equals(two)
        for setting in ("baseline", "fixed"):
            one, two = (pq.read_table(tmp_path / f"ev{w}" / name / f"{setting}.parquet")
                        for w in (1, 2))
            assert one.equals(two)
    # the trajectory names its sequence relative to itself: export finds it from anywhere
    from pipeline.export import export_trajectory

    traj = tmp_path / "a1" / "composite_0" / "trajectory.parquet"
    assert pq.read_schema(traj).metadata[b"adaptune.sequence"] == b"../../composite_0.mcap"
    assert export_trajectory(traj, "tum", tmp_path / "a.tum") == 40


def test_replicas_run_each_setting_with_its_perturbed_parameters(
        tmp_path: Path, validation_set: Path) -> None:
    """evaluate.replicas: replica r of a setting is a run with that setting's parameters times
    the factors of (the sequence, r), scored like the nominal run; the adaptive replica runs
    the schedule times the same factors (a constant schedule of the defaults gives the
    baseline replica's figures); the metrics pool the r-th runs of a split."""
    import numpy as np

    from pipeline.evaluate.replicas import sequence_seed
    from pipeline.evaluate.runs import evaluate
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.metrics.section import DevkitSection
    from pipeline.odometry import get_adapter, run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.report.metrics import metrics
    from pipeline.sequence import SequenceReader
    from pipeline.trajectory import write_trajectory

    path = validation_set / "composite_0.mcap"
    space = get_adapter("ndt").space
    base = space.defaults()
    adaptive = tmp_path / "adaptive" / "composite_0"
    traj = run_sequence(get_adapter("ndt"), path, base)
    Schedule.constant(base, len(traj)).write(adaptive / "schedule.parquet")
    write_trajectory(adaptive / "trajectory.parquet", traj, {"setting": "adaptive"})
    (adaptive / "run.json").write_text(json.dumps({"algorithm": "ndt", "wall_time_s": 1.0}))
    fixed = {"resolution": 2.0, "keyframe_interval": 7.0}
    settings = EvaluateSection(length_m=4.0, devkit=DevkitSection(lengths_m=(4.0,)), replicas=2,
                               replica_scale=0.01)
    ev = evaluate([path], "ndt", fixed, tmp_path / "adaptive", tmp_path / "ev", settings,
                  fixed_dir=_joint_table(tmp_path / "fixed"))
    with SequenceReader(path) as reader:
        gt = reader.ground_truth()
    for setting, params in (("baseline", base), ("fixed", fixed)):
        got = ev.score(setting, "composite_0").replica_rte_pct
        for r in (1, 2):
            f = 1.0 + np.random.default_rng([sequence_seed("composite_0"), r]).uniform(
                -0.01, 0.01, 2)
            moved = {n: params[n] * f[j] for j, n in enumerate(space.names)}
            run = run_sequence(get_adapter("ndt"), path, moved)
            assert got[r - 1] == mean_rte_pct(gt, run.T_world_lidar, 4.0)
    assert (ev.score("adaptive", "composite_0").replica_rte_pct
            == ev.score("baseline", "composite_0").replica_rte_pct)
    m = metrics(ev, {})
    assert m["replicas"] == 2
    runs = m["splits"]["validation"]["replicas"]["baseline"]
    assert runs["rte_pct"] == [ev.score("baseline", "composite_0").rte_pct,
                               *ev.score("baseline", "composite_0").replica_rte_pct]
    assert len(runs["kitti_t_err_pct"]) == 3
    assert m["sequences"]["composite_0"]["replicas_rte_pct"]["fixed"] == (
        ev.score("fixed", "composite_0").replica_rte_pct)


def test_the_report_and_the_metrics_carry_the_warnings(tmp_path: Path, kitti_root: Path,
                                                       validation_set: Path) -> None:
    """evaluate --model: metrics/evaluation.json's ``warnings`` flags follow the validation
    figures and the model's cross-validation (issue 57.5); report.md opens with one sentence
    for every flag set, and the stage prints them."""
    from helpers.models import build_model

    from pipeline.adaptive import run_adaptive
    from pipeline.artifact import read_manifest

    model = build_model(tmp_path / "model", kitti_root)
    run_adaptive(model, [validation_set / "composite_0.mcap"], tmp_path / "adaptive")
    fixed = _joint_table(tmp_path / "fixed")
    (tmp_path / "trials").mkdir()  # no per-sequence study: none to count
    code, out = _invoke(*_evaluate_args(tmp_path, validation_set, fixed, tmp_path / "adaptive"),
                        "--model", str(model))
    assert code == 0, out
    metrics = json.loads((tmp_path / "m.json").read_text())
    rte = metrics["rte_pct"]
    cv = read_manifest(model)["cross_validation"]
    assert metrics["warnings"] == {
        "adaptive_worse_than_baseline": rte["adaptive"] > rte["baseline"],
        "adaptive_worse_than_fixed": rte["adaptive"] > rte["fixed"],
        "surrogate_error_exceeds_rank_gap": cv["mae"] > cv["rank_gap_median"]}
    sentences = json.loads((tmp_path / "r.json").read_text())["warning_text"]
    assert len(sentences) == sum(metrics["warnings"].values())
    report = (tmp_path / "report" / "report.md").read_text()
    for sentence in sentences:
        assert f"> **Warning**: {sentence}." in report and f"warning: {sentence}" in out


def test_warnings_name_their_figures() -> None:
    from pipeline.report.checks import evaluation_warnings, warning_lines

    m = {"headline_split": "train", "splits": {
        "train": {"rte_pct": {"baseline": 1.0, "fixed": 1.0, "adaptive": 9.0}},
        "validation": {"rte_pct": {"baseline": 1.357, "fixed": 2.0, "adaptive": 14.84}}}}
    cv = {"mae": 15.7, "rank_gap_median": 3.2}
    assert evaluation_warnings(m, cv) == {"adaptive_worse_than_baseline": True,
                                          "adaptive_worse_than_fixed": True,
                                          "surrogate_error_exceeds_rank_gap": True}
    assert warning_lines(m, cv) == [
        "adaptive is worse than baseline on the validation split: 14.840 % against 1.357 % "
        "(x10.94)",
        "adaptive is worse than fixed on the validation split: 14.840 % against 2.000 % (x7.42)",
        "the surrogate's cross-validated error (MAE 15.700 %) exceeds the median RTE gap "
        "between the best and the worst trial it ranks at a held-out frame (3.200 %): its "
        "choices of parameters are close to chance"]
    good = {"headline_split": "validation", "splits": {
        "validation": {"rte_pct": {"baseline": 2.0, "fixed": 1.5, "adaptive": 1.0}}}}
    assert evaluation_warnings(good, {"mae": 1.0, "rank_gap_median": 3.0}) == {
        "adaptive_worse_than_baseline": False, "adaptive_worse_than_fixed": False,
        "surrogate_error_exceeds_rank_gap": False}
    assert warning_lines(good, None) == [] and "surrogate_error_exceeds_rank_gap" not in \
        evaluation_warnings(good, {"mae": None, "rank_gap_median": None})
