"""docs/results/verdict.md as rendered from a run's metrics (studies/docs/verdict_page.py):
every target with its figure, interval and verdict; the power from the suite's own spread."""

from __future__ import annotations

import dataclasses

import numpy as np
from helpers.verdict_data import world

from studies.docs.verdict_page import HEADROOM, ID, OOD, SURROGATE_PREFIX, verdict_page
from studies.suites.runner import WorldResult
from studies.verdict.headroom import headroom_metrics
from studies.verdict.section import VerdictSection
from studies.verdict.summary import suite_metrics

HEADER = {"algorithm": "ndt", "suite": "test", "seed_root": 1, "world_generator": 1,
          "length_m": 25.0, "replicas": 0, "replica_scale": 0.005,
          "baseline": {"resolution": 4.0, "keyframe_interval": 4.0},
          "fixed": {"resolution": 2.0, "keyframe_interval": 7.0},
          "fixed_study": {"trials": 64, "pruned": 50}}


VERDICT = VerdictSection()


def suite(family: str, ratio: float, n: int) -> tuple[dict[str, object], list[WorldResult]]:
    rng = np.random.default_rng(len(family))
    worlds = [world(f"{family}_test_{i:02d}",
                    {"baseline": [[2.0, 2.0]], "fixed": [[1.0, 1.0]],
                     "adaptive": [[r, r]]}, ["cave", "street"])
              for i, r in enumerate(ratio * np.exp(rng.normal(0, 0.05, n)))]
    return suite_metrics(worlds, {**HEADER, "family": family}, 10.0, 0.95, 999, 0,
                         targets=VERDICT.targets), worlds


def test_the_page_gives_every_target_its_figure_and_verdict() -> None:
    ids, worlds = suite("id", 0.6, 12)
    ood, _ = suite("ood", 1.2, 6)
    oracles = [WorldResult(w.name, "id", w.segments, w.sensor, w.frames, w.seed, w.labels,
                           {"oracle": np.full((1, 2), 0.5), "class_oracle": np.full((1, 2), 0.9)},
                           {"oracle": [False], "class_oracle": [False]},
                           {"oracle": {"choice": {}}, "class_oracle": {"choice": {}}}, 0.0)
               for w in worlds]
    head = headroom_metrics(worlds, oracles, [HEADER["baseline"]], {**HEADER, "family": "id"},
                            0.95, 999, 0, VERDICT.closed_gap_target)
    models = {f"{SURROGATE_PREFIX}{sensor}.json": {"algorithm": "ndt", "folds": folds,
                                                     "mae": 1.0, "rmse": 2.0, "regret_mean": r}
              for sensor, folds, r in (("hdl32", 12, 0.5), ("hdl64", 11, 0.75))}
    page = verdict_page({ID: ids, OOD: ood, HEADROOM: head, **models},
                        ["> provenance"], {"verdict": {"suite": "test"}})
    targets = page.split("## The targets")[1].split("\n## ")[0]
    rows = [line for line in targets.splitlines() if line.startswith("| id") or
            line.startswith("| ood")]
    assert len(rows) == 6  # id: 2 ratios, closed gap, headroom; ood: 2 ratios
    assert all(" met |" in r for r in rows if r.startswith("| id test: adaptive"))
    ood_rows = {r.split("|")[1].strip(): r for r in rows if r.startswith("| ood")}
    assert ood_rows["ood test: adaptive / fixed"].endswith("**not met** |")  # 1.2 / 1
    assert ood_rows["ood test: adaptive / baseline"].endswith(" met |")  # 1.2 / 2
    gap = next(r for r in rows if "closed gap" in r)
    value = head["closed_gap"]["oracle"]["value"]  # about log(1 / 0.6) / log(1 / 0.5) = 0.74
    assert 0.6 < value < 0.9 and f"| {100 * value:.0f} % (" in gap and gap.endswith(" met |")
    assert "| id test: headroom" in targets and "| headroom |" in targets
    assert "Power: with the spread of its per-world log ratios, this suite of 12 worlds" in page
    assert "verdict: {suite: test}" in page or "suite: test" in page
    models_table = page.split("## The models, one per trained sensor")[1].split("\n## ")[0]
    assert "| hdl32 | ndt | 12 | 1.00 | 2.00 | 0.50 |" in models_table
    assert "| hdl64 | ndt | 11 | 1.00 | 2.00 | 0.75 |" in models_table


def test_a_suite_of_two_sensors_is_also_given_per_sensor() -> None:
    """The HDL-32E's worlds at 0.5 x fixed, the HDL-64E's even with it: each half's own
    geometric mean, wins and worst world, next to the suite's."""
    worlds = [dataclasses.replace(world(f"id_test_{i:02d}",
                                        {"baseline": [[2.0, 2.0]], "fixed": [[1.0, 1.0]],
                                         "adaptive": [[r, r]]}, ["cave", "street"]),
                                  sensor=sensor)
              for i, (sensor, r) in enumerate([("hdl32", 0.5), ("hdl64", 1.0)] * 3)]
    m = suite_metrics(worlds, {**HEADER, "family": "id"}, 10.0, 0.95, 999, 0,
                      targets=VERDICT.targets)
    page = verdict_page({ID: m}, ["> provenance"], {})
    rows = [line for line in page.splitlines() if line.startswith("| hdl")]
    assert rows == ["| hdl32 | 3 | 0.50 | 3 / 3 | 0.50 | 0.25 |",
                    "| hdl64 | 3 | 1.00 | 0 / 3 | 1.00 | 0.50 |"]
    one_sensor = verdict_page({ID: suite("id", 0.6, 4)[0]}, ["> provenance"], {})
    assert "Per sensor" not in one_sensor


def test_the_headroom_is_also_given_per_sensor() -> None:
    """Per sensor, each world's adaptive and oracles against the SBS (the fixed set, 1 %), the
    sensor read from the in-distribution suite of the same worlds: adaptive at 0.8 everywhere,
    the cross-fitted oracle at 0.5 on the HDL-32E and at 2 and 0.5 on the HDL-64E (geometric
    mean 1), the class oracle at 1.5."""
    cases = [("hdl32", 0.5), ("hdl64", 2.0), ("hdl32", 0.5), ("hdl64", 0.5)]
    worlds = [dataclasses.replace(world(f"id_test_{i:02d}",
                                        {"baseline": [[2.0, 2.0]], "fixed": [[1.0, 1.0]],
                                         "adaptive": [[0.8, 0.8]]}, ["cave", "street"]),
                                  sensor=sensor)
              for i, (sensor, _) in enumerate(cases)]
    oracles = [WorldResult(w.name, "id", w.segments, w.sensor, w.frames, w.seed, w.labels,
                           {"oracle": np.full((1, 2), o), "class_oracle": np.full((1, 2), 1.5)},
                           {"oracle": [False], "class_oracle": [False]},
                           {"oracle": {"choice": {}}, "class_oracle": {"choice": {}}}, 0.0)
               for w, (_, o) in zip(worlds, cases, strict=True)]
    header = {**HEADER, "family": "id"}
    ids = suite_metrics(worlds, header, 10.0, 0.95, 999, 0, targets=VERDICT.targets)
    head = headroom_metrics(worlds, oracles, [HEADER["baseline"]], header, 0.95, 999, 0,
                            VERDICT.closed_gap_target)
    section = verdict_page({ID: ids, HEADROOM: head}, ["> provenance"], {}).split(
        "## Headroom on the id test suite")[1].split("\n## ")[0]
    rows = [line for line in section.splitlines() if line.startswith("| hdl")]
    assert rows == ["| hdl32 | 2 | 0.80 (2 / 2) | 0.50 (2 / 2) | 1.50 (0 / 2) |",
                    "| hdl64 | 2 | 0.80 (2 / 2) | 1.00 (1 / 2) | 1.50 (0 / 2) |"]
    other = verdict_page({ID: {**ids, "suite": "dev"}, HEADROOM: head}, ["> provenance"], {})
    assert "to SBS" not in other  # the id suite of other worlds: no split
