"""The verdict's suites: what was frozen, how worlds are drawn, the per-world figures and the
suite's metrics, the oracles' schedules and choices (pipeline/verdict/). The stages run through
DVC on a tiny project in tests/verdict/test_verdict_dvc.py."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers.verdict_data import world

from pipeline.config import load_params, validate_section
from pipeline.errors import ConfigError, InputError
from pipeline.odometry.ndt import SPACE
from pipeline.sim import GENERATOR_VERSION
from pipeline.sim.dataset import SimulateSection
from pipeline.sim.effects import SensorEffects
from pipeline.verdict.headroom import (
    best_per_label,
    candidate_set,
    class_choice,
    held_schedule,
    label_means,
)
from pipeline.verdict.runs import read_results, write_world
from pipeline.verdict.section import VerdictSection
from pipeline.verdict.statistics import geometric_mean
from pipeline.verdict.summary import suite_metrics, targets_met
from pipeline.verdict.worlds import check_generator, sensor_template, suite_worlds

REPO = Path(__file__).resolve().parents[2]
TEMPLATE = sensor_template(SimulateSection(), 42)


def test_the_frozen_values_are_the_codes_defaults_and_the_verdict_params() -> None:
    """verdict/params.yaml validates as a whole, and its verdict section is the code's
    defaults (the values frozen before any result); the root params.yaml's is too."""
    params = load_params(REPO / "verdict" / "params.yaml")
    assert params["verdict"] == VerdictSection()
    assert load_params(REPO / "params.yaml")["verdict"] == VerdictSection()
    frozen = yaml.safe_load((REPO / "verdict" / "params.yaml").read_text())["verdict"]
    assert frozen["suites"]["id"]["seed_roots"] == {"dev": 70101, "test": 87976}
    assert frozen["suites"]["ood"]["seed_roots"] == {"dev": 54912, "test": 37084}
    assert params["fixed"].iterations == 64 and params["fixed"].warm_start == 4


@pytest.mark.parametrize(("change", "rule"), [
    ({"suites": {"id": {"seed_roots": {"dev": 1, "test": 1}, "worlds": 2,
                        "sensors": ["hdl32"]}}}, "the dev and test roots must differ"),
    ({"suites": {"ood": {"seed_roots": {"dev": 70101, "test": 5}, "worlds": 2,
                         "sensors": ["vlp16"]}}}, "every suite needs a seed root of its own"),
    ({"suites": {"id": {"seed_roots": {"dev": 1, "test": 2}, "worlds": 2,
                        "sensors": ["hdl32"], "frames": [60, 60], "segments": [2, 4]}}},
     ">= 30 frames a segment"),
    ({"oracle": {"resolution": []}}, "at least one value"),
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
    write_world(tmp_path / "w", w)
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
    m = suite_metrics(worlds[:3], {"family": "id"}, 10.0, 0.95, 500, 0)
    r = m["ratios"]["adaptive_vs_fixed"]
    assert r["geomean"] == pytest.approx(geometric_mean([0.5, 0.25, 2.0]))
    assert (r["wins"], r["worlds"], r["worst"]) == (2, 3, 2.0)
    assert r["win_rate"]["value"] == pytest.approx(2 / 3)
    assert m["ratios"]["adaptive_vs_baseline"]["geomean"] == pytest.approx(
        geometric_mean([0.5, 0.125, 2.0]))
    assert m["pooled"]["adaptive"]["rte_pct"] == pytest.approx(4 / 3)
    with_failure = suite_metrics(worlds, {"family": "id"}, 10.0, 0.95, 500, 0)
    assert with_failure["pooled"]["adaptive"]["failure_rate"] == pytest.approx(2 / 8)
    assert with_failure["failed_runs"] == {"baseline": 0, "fixed": 0, "adaptive": 1}
    assert with_failure["selector"]["novel_share"] == pytest.approx(0.25)


def test_targets_are_strict_in_distribution_and_not_out_of_it() -> None:
    def ratios(g: float, high: float) -> dict[str, dict[str, float]]:
        return {k: {"geomean": g, "high": high}
                for k in ("adaptive_vs_fixed", "adaptive_vs_baseline")}

    assert targets_met("id", ratios(0.75, 0.89))["adaptive_vs_fixed"]["met"]
    assert not targets_met("id", ratios(0.75, 0.90))["adaptive_vs_fixed"]["met"]
    assert not targets_met("id", ratios(0.76, 0.80))["adaptive_vs_fixed"]["met"]
    assert targets_met("ood", ratios(1.0, 1.05))["adaptive_vs_baseline"]["met"]
    assert not targets_met("ood", ratios(1.0, 1.06))["adaptive_vs_baseline"]["met"]


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
