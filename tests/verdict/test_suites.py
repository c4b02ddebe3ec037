"""The verdict's suites: what was frozen, how worlds are drawn, the per-world figures and the
suite's metrics, the oracles' schedules and choices (studies/verdict/). The stages run through
DVC on a tiny project in tests/verdict/test_verdict_dvc.py."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers.mcap_chunks import chunk_compressions
from helpers.verdict_data import world

from pipeline.config import load_params, validate_section
from pipeline.errors import ConfigError, InputError
from pipeline.odometry.ndt import SPACE
from pipeline.sim import GENERATOR_VERSION
from pipeline.sim.dataset import SimulateSection
from pipeline.sim.effects import SensorEffects
from studies.suites.runner import read_results, write_runs
from studies.suites.statistics import geometric_mean
from studies.verdict.headroom import (
    best_per_label,
    candidate_set,
    class_choice,
    held_schedule,
    label_means,
)
from studies.verdict.section import VerdictSection
from studies.verdict.summary import suite_metrics, targets_met
from studies.verdict.worlds import check_generator, sensor_template, suite_worlds

REPO = Path(__file__).resolve().parents[2]
TARGETS = VerdictSection().targets
TEMPLATE = sensor_template(SimulateSection(), 42)


def test_the_frozen_values_are_the_codes_defaults_and_the_verdict_params() -> None:
    """verdict/params.yaml validates as a whole, and its verdict section is the code's
    defaults (the values frozen before any result); the root params.yaml's is too."""
    params = load_params(REPO / "verdict" / "params.yaml")
    assert params["verdict"] == VerdictSection()
    assert load_params(REPO / "params.yaml")["verdict"] == VerdictSection()
    copy = yaml.safe_load((REPO / "verdict" / "params.yaml").read_text())
    got = {key: _at(copy, key) for key in FROZEN}
    assert got == FROZEN  # a toy edit (params.yaml) never moves them: the copy is its own
    assert params["fixed"].iterations == 64 and params["fixed"].warm_start == 4


FROZEN: dict[str, object] = {
    "verdict.suites.id.seed_roots": {"dev": 70101, "test": 87976},
    "verdict.suites.ood.seed_roots": {"dev": 54912, "test": 37084},
    "verdict.tuning.seed_root": 45453,
    "verdict.world_generator": 2,
    "verdict.baseline": {"resolution": 4.0, "keyframe_interval": 4.0},
    "verdict.fixed_trials": 64,
    "verdict.fixed_warm_start": 4,
    "verdict.failure_pct": 10.0,
    "portfolio.grid": {"resolution": [1.0, 1.5, 2.0, 3.0, 4.5, 7.0],
                       "keyframe_interval": [0.0, 2.0, 4.0, 7.0, 10.0]},
}
"""The values verdict/params.yaml froze before any result (docs/results/verdict-protocol.md):
the suites' seed roots, the world generator, the baseline, the fixed study's least budget, the
failure threshold and the oracle's candidate grid (the portfolio's)."""


def _at(params: dict[str, object], key: str) -> object:
    value: object = params
    for part in key.split("."):
        value = value[part]  # type: ignore[index]
    return value


@pytest.mark.parametrize(("change", "rule"), [
    ({"suites": {"id": {"seed_roots": {"dev": 1, "test": 1}, "worlds": 2,
                        "sensors": ["hdl32"]}}}, "the dev and test roots must differ"),
    ({"suites": {"ood": {"seed_roots": {"dev": 70101, "test": 5}, "worlds": 2,
                         "sensors": ["vlp16"]}}}, "every suite needs a seed root of its own"),
    ({"suites": {"id": {"seed_roots": {"dev": 1, "test": 2}, "worlds": 2,
                        "sensors": ["hdl32"], "frames": [60, 60], "segments": [2, 4]}}},
     ">= 30 frames a segment"),
    ({"borrow_model": "vlp16"}, "borrow_model must be a trained sensor \\(hdl32, hdl64\\) or "
                                "null, got 'vlp16'"),
])
def test_bad_verdict_sections_name_the_rule(change: dict[str, object], rule: str) -> None:
    with pytest.raises(ConfigError, match=rule):
        validate_section(VerdictSection, "verdict", change)


def test_world_i_depends_on_its_root_and_i_alone() -> None:
    section = VerdictSection()
    worlds = suite_worlds(section, "id", TEMPLATE)
    fewer = VerdictSection.model_validate(
        {"suites": {"id": {**section.suites.id.model_dump(), "worlds": 5}}})
    assert suite_worlds(fewer, "id", TEMPLATE) == worlds[:5]
    dev = suite_worlds(section.model_copy(update={"suite": "dev"}), "id", TEMPLATE)
    ood = suite_worlds(section, "ood", TEMPLATE)
    seeds = [{w.spec.seed for w in ws} for ws in (worlds, dev, ood)]
    assert all(a.isdisjoint(b) for a, b in itertools.combinations(seeds, 2))
    assert [w.name for w in worlds[:2]] == ["id_test_00", "id_test_01"]
    assert [w.name for w in dev[:1]] == ["id_dev_00"]


def test_worlds_follow_the_draw_and_the_training_sensor_model() -> None:
    section = VerdictSection()
    effects = SensorEffects.ideal(range_noise_m=0.05, dropout=0.02)
    simulate = SimulateSection(effects=effects, motion="compensated")
    for family in ("id", "ood"):
        draw = section.suites.draw(family)
        worlds = suite_worlds(section, family, sensor_template(simulate, 42))
        assert len(worlds) == draw.worlds
        for i, w in enumerate(worlds):
            segs = w.spec.segments
            assert 2 <= len(segs) <= 4 and all(a != b for a, b in itertools.pairwise(segs))
            assert 900 <= w.spec.frames <= 1200
            assert w.spec.sensor == draw.sensors[i % len(draw.sensors)]
            assert (w.spec.effects, w.spec.motion) == (effects, "compensated")
            w.spec.check()
    ids = suite_worlds(section, "id", TEMPLATE)
    assert {w.spec.sensor for w in ids} == {"hdl32", "hdl64"}
    assert {lab for w in ids for lab in w.spec.segments} == {"cave", "open", "street"}


def test_another_world_generator_is_refused() -> None:
    other = GENERATOR_VERSION + 1
    with pytest.raises(ConfigError, match=rf"frozen with world generator {other}, this code "
                                          rf"simulates version {GENERATOR_VERSION}"):
        check_generator(VerdictSection(world_generator=other))


LABELS = ["cave", "cave", "street", "street"]


def test_a_worlds_figure_is_the_median_over_its_runs(tmp_path: Path) -> None:
    nan = math.nan
    w = world("w", {"baseline": [[1, 1, 1, nan], [2, 2, 2, nan], [9, 9, 9, nan]],
                    "fixed": [[4, 4, 4, nan], [4, 4, 4, nan], [4, 4, 4, nan]],
                    "adaptive": [[1, 3, 1, nan], [1, 1, 1, nan], [100, 100, 100, nan]]},
              LABELS)
    assert w.run_rte("adaptive").tolist() == pytest.approx([5 / 3, 1.0, 100.0])
    assert w.median("baseline") == 2.0 and w.median("adaptive") == pytest.approx(5 / 3)
    assert w.ratio("adaptive", "fixed") == pytest.approx(5 / 12)
    assert w.ratio("adaptive", "min") == pytest.approx(5 / 6)  # min(baseline 2, fixed 4)
    assert w.median("adaptive", "street") == 1.0  # the street frame of each run: 1, 1, 100
    write_runs(tmp_path / "w", w)
    back = read_results(tmp_path)[0]
    assert back.name == "w" and back.labels == LABELS
    for s in w.settings:
        np.testing.assert_array_equal(back.t_err_pct[s], w.t_err_pct[s])


def test_suite_metrics_by_hand() -> None:
    """Three worlds; adaptive / fixed per world 0.5, 0.25, 2: geometric mean 0.63; two wins
    of three; a failed run's penalty counts in the pooled RTE and the failure rate."""
    worlds = [world(f"w{i}", {"baseline": [[b, b]], "fixed": [[f, f]], "adaptive": [[a, a]]},
                    ["cave", "street"])
              for i, (b, f, a) in enumerate([(2, 2, 1), (8, 4, 1), (1, 1, 2)])]
    worlds.append(world("w3", {"baseline": [[1, 1]], "fixed": [[1, 1]], "adaptive": [[100, 100]]},
                        ["cave", "street"], {"baseline": [False], "fixed": [False],
                                             "adaptive": [True]}))
    m = suite_metrics(worlds[:3], {"family": "id"}, 10.0, 0.95, 500, 0,
                      targets=TARGETS)
    r = m["ratios"]["adaptive_vs_fixed"]
    assert r["geomean"] == pytest.approx(geometric_mean([0.5, 0.25, 2.0]))
    assert (r["wins"], r["worlds"], r["worst"]) == (2, 3, 2.0)
    assert r["win_rate"]["value"] == pytest.approx(2 / 3)
    assert m["ratios"]["adaptive_vs_baseline"]["geomean"] == pytest.approx(
        geometric_mean([0.5, 0.125, 2.0]))
    assert m["pooled"]["adaptive"]["rte_pct"] == pytest.approx(4 / 3)
    with_failure = suite_metrics(worlds, {"family": "id"}, 10.0, 0.95, 500, 0,
                                 targets=TARGETS)
    assert with_failure["pooled"]["adaptive"]["failure_rate"] == pytest.approx(2 / 8)
    assert with_failure["failed_runs"] == {"baseline": 0, "fixed": 0, "adaptive": 1}
    assert with_failure["selector"]["novel_share"] == pytest.approx(0.25)


def test_targets_are_strict_in_distribution_and_not_out_of_it() -> None:
    def ratios(g: float, high: float) -> dict[str, dict[str, float]]:
        return {k: {"geomean": g, "high": high}
                for k in ("adaptive_vs_fixed", "adaptive_vs_baseline")}

    assert targets_met("id", ratios(0.75, 0.89), TARGETS)["adaptive_vs_fixed"]["met"]
    assert not targets_met("id", ratios(0.75, 0.90), TARGETS)["adaptive_vs_fixed"]["met"]
    assert not targets_met("id", ratios(0.76, 0.80), TARGETS)["adaptive_vs_fixed"]["met"]
    assert targets_met("ood", ratios(1.0, 1.05), TARGETS)["adaptive_vs_baseline"]["met"]
    assert not targets_met("ood", ratios(1.0, 1.06), TARGETS)["adaptive_vs_baseline"]["met"]


def test_the_candidate_set_is_the_grid_the_baseline_and_the_fixed_set() -> None:
    grid = {"resolution": [1.0, 4.0], "keyframe_interval": [0.0, 4.0]}
    fixed = {"resolution": 2.5, "keyframe_interval": 7.0}
    sets = candidate_set(grid, SPACE.defaults(), fixed, SPACE)
    assert len(sets) == 5  # the baseline (4, 4) is already in the grid
    assert sets[-1] == fixed and SPACE.defaults() in sets
    with pytest.raises(InputError, match="not the studies'"):
        candidate_set({"resolution": [1.0]}, SPACE.defaults(), fixed, SPACE)


def test_the_oracle_holds_each_choice_for_a_period() -> None:
    """A selection every second (10 frames at 10 Hz): the label of the selection frame holds
    until the next one, whatever the labels of the frames in between."""
    labels = ["cave"] * 13 + ["street"] * 12
    stamps = np.arange(25, dtype=np.int64) * 100_000_000
    cave, street = {"resolution": 1.0, "keyframe_interval": 2.0}, {
        "resolution": 6.0, "keyframe_interval": 9.0}
    default = {"resolution": 4.0, "keyframe_interval": 4.0}
    s = held_schedule(labels, stamps, {"cave": cave, "street": street}, default, 1.0)
    res = s.values["resolution"]
    assert res[:20].tolist() == [1.0] * 20  # frames 10-19: the cave of frame 10
    assert res[20:].tolist() == [6.0] * 5
    assert held_schedule(labels, stamps, {"cave": cave}, default, 1.0).values[
        "resolution"][20:].tolist() == [4.0] * 5  # no choice for the street: the default
    assert s.n_changes == 1


def test_the_oracles_choose_per_label() -> None:
    t = np.array([1.0, 3.0, 2.0, 5.0, np.nan])
    assert label_means(t, ["cave", "cave", "open", "open", "open"]) == {"cave": 2.0,
                                                                         "open": 3.5}
    assert best_per_label({"cave": [3.0, 1.0, 1.0], "open": [np.nan, 2.0, 1.0]}) == {
        "cave": 1, "open": 2}
    # class oracle of world a: the candidate best on the other worlds, relative to each
    # world's median candidate (b's caves are 10x harder, but rank candidate 2 best)
    label_rte = {"a": {"cave": [1.0, 2.0, 3.0]}, "b": {"cave": [30.0, 20.0, 5.0]},
                 "c": {"cave": [3.0, 2.5, 2.0], "open": [1.0, 1.0, 1.0]}}
    assert class_choice("a", label_rte) == {"cave": 2}
    assert class_choice("c", label_rte) == {"cave": 2}  # "open" only on c: no class choice


def test_the_tuning_suite_is_drawn_as_the_id_suites_from_its_own_root() -> None:
    """verdict.tuning: worlds id_tune_<i> of the id draw (sensors alternate, 900-1200 frames,
    2-4 segments) from the frozen root 45453, none of them a dev or test world; the index lists
    every world under train and each sensor's under its name; a root a suite uses is refused."""
    from studies.verdict.tuning import tuning_index, tuning_worlds

    section = VerdictSection()
    assert (section.tuning.seed_root, section.tuning.worlds) == (45453, 24)
    worlds = tuning_worlds(section, TEMPLATE)
    assert [w.name for w in worlds[:2]] == ["id_tune_00", "id_tune_01"] and len(worlds) == 24
    assert [w.spec.sensor for w in worlds[:4]] == ["hdl32", "hdl64", "hdl32", "hdl64"]
    assert all(900 <= w.spec.frames <= 1200 and 2 <= len(w.spec.segments) <= 4 for w in worlds)
    assert worlds[0].description == "cave-street-open-street, hdl32, 1169 frames"
    suites = [suite_worlds(section.model_copy(update={"suite": s}), f, TEMPLATE)
              for s in ("dev", "test") for f in ("id", "ood")]
    assert {w.spec.seed for w in worlds}.isdisjoint({w.spec.seed for ws in suites for w in ws})
    index = tuning_index(worlds)
    assert index["train"] == [w.name for w in worlds] and index["validation"] == []
    assert index["hdl32"] == [f"id_tune_{i:02d}" for i in range(0, 24, 2)]
    assert index["hdl64"] == [f"id_tune_{i:02d}" for i in range(1, 24, 2)]
    with pytest.raises(ConfigError, match=r"tuning\.seed_root must differ from every suite's "
                                          r"root, got 87976"):
        validate_section(VerdictSection, "verdict", {"tuning": {"seed_root": 87976}})


def test_a_model_folder_per_sensor_gives_each_world_its_sensors_artifact(tmp_path: Path) -> None:
    """--model is one artifact (every world runs it) or a folder of one per sensor; a sensor
    without one (the VLP-16, kept out of training) borrows another's (verdict.borrow_model), or
    gets None: its worlds run the fixed set. A folder holding neither is refused before any
    world runs."""
    from studies.suites.runner import AdaptiveSetting

    one = tmp_path / "model"
    one.mkdir()
    (one / "manifest.json").write_text("{}")
    assert AdaptiveSetting(one).model_for("vlp16") == one
    per_sensor = tmp_path / "models"
    for sensor in ("hdl32", "hdl64"):
        (per_sensor / sensor).mkdir(parents=True)
        (per_sensor / sensor / "manifest.json").write_text("{}")
    setting = AdaptiveSetting(per_sensor)
    setting.check()
    assert setting.model_for("hdl64") == per_sensor / "hdl64"
    assert setting.model_for("vlp16") is None
    borrowing = AdaptiveSetting(per_sensor, borrow="hdl64")
    assert borrowing.model_for("vlp16") == per_sensor / "hdl64"
    assert borrowing.model_for("hdl32") == per_sensor / "hdl32"  # its own first
    assert AdaptiveSetting(per_sensor, borrow="ouster").model_for("vlp16") is None
    (tmp_path / "empty" / "hdl32").mkdir(parents=True)
    with pytest.raises(InputError, match="neither an artifact"):
        AdaptiveSetting(tmp_path / "empty").check()


def test_a_world_whose_sensor_has_no_model_runs_the_fixed_set(tmp_path: Path) -> None:
    """A per-sensor model folder without the VLP-16's: the VLP-16 world's adaptive is the
    fixed set, its runs fixed's (not run again), no schedule written, every scan unfamiliar."""
    from studies.suites.runner import AdaptiveSetting, SuiteInputs, score_world
    from studies.verdict.section import SuiteDraw
    from studies.verdict.worlds import world_of

    models = tmp_path / "models" / "hdl32"
    models.mkdir(parents=True)
    (models / "manifest.json").write_text("{}")  # never loaded: no world here is an HDL-32E
    draw = SuiteDraw(seed_roots={"dev": 1, "test": 2}, worlds=1, sensors=("vlp16",),
                     segments=(2, 2), frames=(60, 60))
    w = world_of(draw, "ood", "dev", 0, TEMPLATE)
    fixed = {"resolution": 2.0, "keyframe_interval": 1.0}
    inputs = SuiteInputs("ndt", SPACE, SPACE.defaults(), fixed, {}, 4.0, 1, 0.005, 100.0,
                         {"adaptive": AdaptiveSetting(models.parent)})
    result = score_world(w, inputs, tmp_path / "runs")
    assert np.array_equal(result.t_err_pct["adaptive"], result.t_err_pct["fixed"],
                          equal_nan=True)
    assert not np.array_equal(result.t_err_pct["baseline"], result.t_err_pct["fixed"],
                              equal_nan=True)
    assert result.selection["adaptive"] == {"changes": 0, "novel_share": 1.0, "edge_share": 0.0}
    assert not list((tmp_path / "runs").rglob("*.schedule.parquet"))


def test_the_tuning_suite_stage_writes_the_worlds_and_their_index(tmp_path: Path) -> None:
    """``adaptune tuning-suite``: every tuning world an MCAP, the index last, with its sensor
    split (two tiny VLP-16 worlds here)."""
    import json

    from click.testing import CliRunner

    from pipeline.sequence import SequenceReader
    from stages.cli import main

    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"verdict": {
        "tuning": {"seed_root": 5, "worlds": 2}, "workers": 1, "borrow_model": None,
        "suites": {"id": {"seed_roots": {"dev": 1, "test": 2}, "worlds": 1,
                          "sensors": ["vlp16"], "segments": [2, 2], "frames": [60, 60]}}}}))
    out = tmp_path / "tune"
    res = CliRunner().invoke(main, ["tuning-suite", "--params", str(params), "--out", str(out)])
    assert res.exit_code == 0, res.output
    index = json.loads((out / "index.json").read_text())
    assert index == {"train": ["id_tune_00", "id_tune_01"], "validation": [],
                     "vlp16": ["id_tune_00", "id_tune_01"]}
    for name in index["train"]:
        with SequenceReader(out / f"{name}.mcap") as reader:
            assert len(reader.stamps_ns) == 60 and len(reader.info.labels) == 2
        assert chunk_compressions(out / f"{name}.mcap") == {""}  # verdict.tuning.compression
    assert sorted(p.name for p in out.iterdir()) == ["id_tune_00.mcap", "id_tune_01.mcap",
                                                    "index.json"]


def test_the_tuning_suite_refuses_an_unknown_compression(tmp_path: Path) -> None:
    """``verdict.tuning.compression: lz4`` ends ``adaptune tuning-suite`` in one line naming
    the setting and exit code 1, before any world is written."""
    from click.testing import CliRunner

    from stages.cli import main

    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"verdict": {"tuning": {"compression": "lz4"}}}))
    out = tmp_path / "tune"
    res = CliRunner().invoke(main, ["tuning-suite", "--params", str(params), "--out", str(out)])
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "verdict.tuning.compression" in lines[0] and "lz4" in lines[0]
    assert not out.exists()
