"""docs/results/verdict.md, rendered from the coverage pipeline's committed metrics
(verdict/metrics/{id,ood,headroom}.json and surrogate_<sensor>.json, one per trained sensor's
model; ``make docs``, ``studies.docs.pages``).

The page gives every target of the protocol with its figure and interval, then per suite the ratios
(geometric mean, interval, win rate and its Wilson interval, worst world), the pooled RTE and
failure rate of every setting, what the selector did, the power analysis from the suite's own
spread, the headroom and the closed gap, the history of every earlier run on the test suites
(docs/results/verdict-history.yaml), every world, and the params of the run."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from studies.docs.markdown import fill as _fill
from studies.docs.markdown import number as _f
from studies.docs.markdown import params_section
from studies.docs.markdown import percent as _pct
from studies.docs.markdown import table as _table
from studies.docs.markdown import values as _values
from studies.docs.verdict_history import History, history_section
from studies.suites.statistics import geometric_mean, worlds_needed

ID, OOD, HEADROOM = ("verdict/metrics/id.json", "verdict/metrics/ood.json",
                      "verdict/metrics/headroom.json")
METRICS = (ID, OOD, HEADROOM)
"""The suites' metrics the page quotes (the headroom's only when its stage has run)."""
SURROGATE_PREFIX = "verdict/metrics/surrogate_"
"""Each trained sensor's model: ``verdict/metrics/surrogate_<sensor>.json`` (verdict/dvc.yaml's
``surrogate`` stages), with its record beside it."""


def surrogate_sensor(name: str) -> str | None:
    """The sensor of a model's metrics file ``name`` (None for any other file)."""
    if name.startswith(SURROGATE_PREFIX) and name.endswith(".json"):
        return name.removeprefix(SURROGATE_PREFIX).removesuffix(".json")
    return None


TITLES = {"adaptive_vs_fixed": "adaptive / fixed", "adaptive_vs_baseline": "adaptive / baseline",
          "adaptive_vs_best": "adaptive / min(baseline, fixed)",
          "fixed_vs_baseline": "fixed / baseline", "adaptive_vs_sbs": "adaptive / SBS",
          "oracle_vs_sbs": "cross-fitted oracle / SBS",
          "class_oracle_vs_sbs": "class oracle / SBS"}
FAMILY_TITLES = {"id": "in distribution (trained environments and sensors)",
                 "ood": "out of distribution (VLP-16, a sensor kept out of training)"}


def verdict_page(metrics: Mapping[str, Mapping[str, Any]], provenance: Sequence[str],
                 params: Mapping[str, Any], history: History | None = None) -> str:
    """The page's text (module docstring); ``provenance``: its quoted header lines;
    ``history``: every earlier run on the test suites (``studies.docs.verdict_history``)."""
    suites = [metrics[name] for name in (ID, OOD) if name in metrics]
    head = metrics.get(HEADROOM)
    lines = ["# The verdict: adaptive against the best fixed parameters on unseen worlds", "",
             *provenance, "",
             "What was frozen, the statistics and the power analysis's method: "
             "[verdict-protocol.md](verdict-protocol.md).", "",
             *_targets(suites, head), ""]
    for m in suites:
        lines += [*_suite(m), ""]
    if head is not None:
        lines += [*_headroom(head), *_headroom_per_sensor(head, metrics.get(ID)), ""]
    models = {sensor: m for n, m in metrics.items() if (sensor := surrogate_sensor(n))}
    if models:
        lines += [*_models(models), ""]
    if history is not None:
        lines += [*history_section(history), ""]
    for m in suites:
        lines += [*_worlds(m), ""]
    lines += params_section(params, "verdict/params.yaml")
    return _fill("\n".join(lines)) + "\n"


def _interval(s: Mapping[str, Any], digits: int = 2) -> str:
    if s["low"] is None or s["high"] is None:
        return f"{_f(s['geomean'], digits)} (no interval)"
    return f"{_f(s['geomean'], digits)} ({_f(s['low'], digits)}-{_f(s['high'], digits)})"


def _rate(w: Mapping[str, Any]) -> str:
    if w["value"] is None:
        return "-"
    return f"{100 * w['value']:.0f} % ({100 * w['low']:.0f}-{100 * w['high']:.0f} %)"


def _targets(suites: Sequence[Mapping[str, Any]], head: Mapping[str, Any] | None) -> list[str]:
    rows: list[list[object]] = []
    for m in suites:
        for name, t in m["targets"].items():
            most, upper = t["geomean_at_most"], t["upper_end"][1]
            s = m["ratios"][name]
            sign = "<" if m["family"] == "id" else "<="
            rows.append([f"{m['family']} {m['suite']}: {TITLES[name]}",
                         f"<= {most:g}, upper end {sign} {upper:g}", _interval(s),
                         "met" if t["met"] else "**not met**"])
    if head is not None:
        gap = head["closed_gap"]["oracle"]
        rows.append([f"id {head['suite']}: closed gap (cross-fitted oracle)",
                     f">= {100 * head['targets']['closed_gap']['at_least']:.0f} %, lower end > 0",
                     f"{_pct(gap['value'])} ({_pct(gap['low'])} to {_pct(gap['high'])})",
                     "met" if head["targets"]["closed_gap"]["met"] else "**not met**"])
        o = head["ratios"]["oracle_vs_sbs"]
        rows.append([f"id {head['suite']}: headroom, cross-fitted oracle / SBS",
                     "interval below 1 (else the method cannot win here)", _interval(o),
                     "headroom" if head["headroom"] else "**no headroom**"])
    return ["## The targets", "",
            "Geometric means of per-world ratios (each world: the median over its runs) with "
            "their 95 % bootstrap intervals:", "",
            *_table(["figure", "target", "measured", ""], rows)]


def _suite(m: Mapping[str, Any]) -> list[str]:
    runs = 1 + int(m["replicas"])
    ratio_rows = [[TITLES[name], _interval(s), _rate(s["win_rate"]),
                   f"{s['wins']} / {s['worlds']}", _f(s["worst"], 2), _f(s["log_spread"], 2),
                   _f(s["detectable_ratio"], 2)]
                  for name, s in m["ratios"].items()]
    labels = sorted({lab for per in m["pooled_per_label"].values() for lab in per})
    pooled_rows = [[setting, _f(p["rte_pct"]), _pct(p["failure_rate"]),
                    *(f"{_f(m['pooled_per_label'][setting][lab]['rte_pct'])} / "
                      f"{_pct(m['pooled_per_label'][setting][lab]['failure_rate'])}"
                      for lab in labels)]
                   for setting, p in m["pooled"].items()]
    sel = m["selector"]
    return [f"## {FAMILY_TITLES.get(m['family'], m['family'])}: the {m['suite']} suite", "",
            f"Seed root {m['seed_root']}, world generator {m['world_generator']}: "
            f"{m['worlds']} worlds, {m['frames']} frames, {runs} runs of every setting on "
            f"every world (parameters moved by at most {100 * m['replica_scale']:g} % in the "
            f"replicas), L = {m['length_m']:g} m. Baseline {_values(m['baseline'])}; fixed "
            f"(the joint study: {m['fixed_study']['trials']} trials, "
            f"{m['fixed_study']['pruned']} pruned) {_values(m['fixed'])}.", "",
            *_table(["ratio", "geometric mean (95 % interval)", "win rate (Wilson 95 %)",
                     "wins", "worst world", "spread of log ratios",
                     "smallest detectable ratio"], ratio_rows), "",
            f"Pooled over every sub-trajectory of every run (RTE [%] / share above the failure "
            f"threshold of {m['failure_pct']:g} %):", "",
            *_table(["setting", "RTE [%]", "failures", *labels], pooled_rows), "",
            f"The selector: {_f(sel['changes'], 1)} parameter changes a world, "
            f"{_pct(sel['novel_share'])} of its selections fell back on an unfamiliar scan, "
            f"{_pct(sel['edge_share'])} of the frames ran with a parameter at the edge of its "
            f"range. Failed runs: "
            + ", ".join(f"{s} {n}" for s, n in m["failed_runs"].items()) + ".", "",
            *_per_sensor(m), *_power(m)]


def _per_sensor(m: Mapping[str, Any]) -> list[str]:
    """The suite's worlds split by sensor (a suite of more than one): geometric means of the
    per-world ratios, wins and the worst world, without intervals (the split is not sized)."""
    by_sensor: dict[str, list[Mapping[str, float]]] = {}
    for w in m["per_world"].values():
        by_sensor.setdefault(w["sensor"], []).append(w["ratios"])
    if len(by_sensor) < 2:
        return []
    rows = []
    for sensor, ratios in by_sensor.items():
        af = np.array([r["adaptive_vs_fixed"] for r in ratios])
        ab = [r["adaptive_vs_baseline"] for r in ratios]
        rows.append([sensor, len(ratios), _f(geometric_mean(af), 2),
                     f"{int((af < 1).sum())} / {len(af)}", _f(float(af.max()), 2),
                     _f(geometric_mean(ab), 2)])
    return ["Per sensor (geometric means of the per-world ratios; no intervals: the suite is "
            "sized as a whole, not per sensor):", "",
            *_table(["sensor", "worlds", "adaptive / fixed", "wins", "worst world",
                     "adaptive / baseline"], rows), ""]


def _power(m: Mapping[str, Any]) -> list[str]:
    """What the suite's own spread says about its size (docs/results/verdict-protocol.md)."""
    s = m["ratios"]["adaptive_vs_fixed"]
    spread = s["log_spread"]
    if spread is None:
        return []
    needs = []
    for name, t in m["targets"].items():
        most, upper = t["geomean_at_most"], t["upper_end"][1]
        sd = m["ratios"][name]["log_spread"]
        n = worlds_needed(sd, most, upper) if sd is not None else None
        needs.append(f"{TITLES[name]} (spread {_f(sd, 2)}): "
                     + (f"{n} worlds" if n is not None else "more than 10000 worlds"))
    return [f"Power: with the spread of its per-world log ratios, this suite of {s['worlds']} "
            f"worlds detects a geometric-mean ratio of {_f(s['detectable_ratio'], 2)} "
            "(adaptive / fixed; 95 % interval excluding 1 with 80 % power). To show a true "
            "ratio at the target's geometric mean below the target's upper end with 80 % "
            "power, the same spread needs: " + "; ".join(needs) + "."]


def _headroom(h: Mapping[str, Any]) -> list[str]:
    rows = [[TITLES[name], _interval(s), _rate(s["win_rate"]), _f(s["worst"], 2)]
            for name, s in h["ratios"].items()]
    gaps = [[f"{name.replace('_', ' ')}", _pct(g["value"]),
             f"{_pct(g['low'])} to {_pct(g['high'])}"]
            for name, g in h["closed_gap"].items()]
    return [f"## Headroom on the id {h['suite']} suite", "",
            f"{h['worlds']} worlds; {len(h['candidates'])} candidate sets (the frozen grid, the "
            "baseline and the fixed set). The cross-fitted oracle chooses per world and label "
            "on a replica the suite never runs and is scored on the suite's runs; the class "
            "oracle carries each label's best set over from the other worlds.", "",
            *_table(["ratio", "geometric mean (95 % interval)", "win rate", "worst world"], rows),
            "", "Closed gap, log(SBS / adaptive) / log(SBS / oracle):", "",
            *_table(["oracle", "closed gap", "95 % interval"], gaps)]


def _headroom_per_sensor(h: Mapping[str, Any], suite: Mapping[str, Any] | None) -> list[str]:
    """The headroom's worlds split by sensor, each world's sensor read from the in-distribution
    suite's metrics of the same suite (the oracles ran on its worlds): geometric means of each
    world's adaptive, cross-fitted oracle and class oracle RTE against the SBS's, no intervals.
    Nothing without that suite or with a single sensor."""
    if suite is None or suite.get("suite") != h["suite"]:
        return []
    sensor_of = {name: w["sensor"] for name, w in suite["per_world"].items()}
    by_sensor: dict[str, list[Mapping[str, float]]] = {}
    for name, w in h["per_world"].items():
        if name in sensor_of:
            by_sensor.setdefault(sensor_of[name], []).append(w)
    if len(by_sensor) < 2:
        return []
    names = ("adaptive", "oracle", "class_oracle")
    rows = []
    for sensor, worlds in by_sensor.items():
        ratios = {k: np.array([w[f"{k}_rte_pct"] / w["sbs_rte_pct"] for w in worlds])
                  for k in names}
        rows.append([sensor, len(worlds),
                     *(f"{_f(geometric_mean(ratios[k]), 2)} ({int((ratios[k] < 1).sum())} / "
                       f"{len(worlds)})" for k in names)])
    return ["", "Per sensor (geometric means of the per-world ratios to SBS, in brackets the "
            "worlds below 1; no intervals: the suite is sized as a whole, not per sensor):", "",
            *_table(["sensor", "worlds", "adaptive / SBS", "cross-fitted oracle / SBS",
                     "class oracle / SBS"], rows)]


def _models(models: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Each trained sensor's model: its leave-one-world-out figures on its tuning worlds."""
    rows = [[sensor, cv["algorithm"], cv["folds"], _f(cv["mae"], 2), _f(cv["rmse"], 2),
             _f(cv["regret_mean"], 2)] for sensor, cv in models.items()]
    return ["## The models, one per trained sensor", "",
            "Each is fitted on its sensor's worlds of the tuning suite; a sensor without a model "
            "borrows `verdict.borrow_model`'s. Leave one tuning world out (RTE [%]):", "",
            *_table(["sensor", "algorithm", "worlds", "MAE", "RMSE", "mean regret"], rows)]


def _worlds(m: Mapping[str, Any]) -> list[str]:
    rows = [[name, w["sensor"], "-".join(s[0] for s in w["segments"]), w["frames"],
             *(_f(w["median_rte_pct"][s]) for s in ("baseline", "fixed", "adaptive")),
             _f(w["ratios"]["adaptive_vs_fixed"], 2), _f(w["ratios"]["adaptive_vs_baseline"], 2),
             w["selection"].get("changes", "-"), _pct(w["selection"].get("novel_share"))]
            for name, w in m["per_world"].items()]
    return [f"<details><summary>Every world of the {m['family']} {m['suite']} suite (median "
            "RTE [%] over the runs; segments c/o/s: cave/open/street)</summary>", "",
            *_table(["world", "sensor", "segments", "frames", "baseline", "fixed", "adaptive",
                     "a / f", "a / b", "changes", "unfamiliar"], rows), "", "</details>"]
