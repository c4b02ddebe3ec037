"""docs/results/real.md, rendered from the real-data pipeline's committed metrics
(real/metrics/real.json; ``make docs``, ``studies.docs.pages``).

The page gives every target with its figures, then per algorithm and family every fold's test
runs: each ratio over the sub-trajectories both settings finished (with its moving-block
interval) and over all of them (a failure at the penalty), the failure rates, the reference's
floor as a ratio to the fixed set, where the selector fell back and the k its fold chose; the
families' geometric means; the cost of every step; the units and how close each run's halves
come; the top view of the frozen fold; the params of the run."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from studies.docs.markdown import fill as _fill
from studies.docs.markdown import number as _f
from studies.docs.markdown import params_section
from studies.docs.markdown import percent as _pct
from studies.docs.markdown import table as _table

METRICS = "real/metrics/real.json"
FIGURE = "real-topview.png"
"""The top view of the frozen fold, beside the page (docs/results/, the report stage's)."""
FAMILY_TITLES = {"in_distribution": "In distribution: every run's other half trained on "
                                    "(folds in_a, in_b)",
                 "out_of_environment": "Out of environment: a hand-held run left out, the "
                                       "other two trained on (folds out_<run>)"}
TITLES = {"fixed_vs_baseline": "fixed / baseline", "adaptive_vs_fixed": "adaptive / fixed",
          "adaptive_vs_baseline": "adaptive / baseline",
          "adaptive_vs_in_sample": "adaptive / in-sample best",
          "fixed_vs_in_sample": "fixed / in-sample best"}
TARGET_TITLES = {
    "tuning_pays": "tuning pays: fixed / baseline, in distribution, per algorithm",
    "adapting_pays_in_distribution": "adaptive / fixed in distribution (two of three "
                                     "algorithms at most)",
    "out_of_environment": "adaptive / fixed out of environment",
    "worst_run": "any single run of a fold: adaptive / fixed"}


def real_page(m: Mapping[str, Any], provenance: Sequence[str],
              params: Mapping[str, Any]) -> str:
    """The page's text (module docstring); ``provenance``: its quoted header lines."""
    lines = ["# Real runs: does tuning, and does adapting, pay?", "", *provenance, "",
             *_reading(m), "", *_targets(m), ""]
    for algorithm in m["algorithms"]:
        lines += [*_algorithm(algorithm, m["by_algorithm"][algorithm]), ""]
    lines += [*_units(m), "", *_figure(m), "",
              *params_section(params, "real/params.yaml")]
    return _fill("\n".join(lines)) + "\n"


def _reading(m: Mapping[str, Any]) -> list[str]:
    failures = ", ".join(f"{v:g} % at L = {k} m" for k, v in m["failure_pct"].items())
    return [
        "Four real runs (../shared/data/real): three hand-held with a solid-state sensor of "
        "about 80 deg field of view (hku_1, hku_mb, quick_shack) and a 2.4 km drive with an "
        "Ouster OS1-64 (riverside02). The reference is a LiDAR-inertial SLAM system's "
        "loop-closed poses, not survey-grade: its own odometry before loop closure, scored "
        "against it on the same sub-trajectories, is the *floor* printed beside every run (a "
        "lower bound on what the reference can tell apart, not a competitor).", "",
        "Every setting ran "
        f"{m['replicas'] + 1} times (the nominal parameters and {m['replicas']} replicas "
        "moved by at most 0.5 %); a start frame's RTE is the median over them. A ratio of "
        "two settings is the ratio of their mean RTE over a run's start frames, with a 95 % "
        "moving-block bootstrap interval (blocks of the frames one sub-trajectory spans). "
        "Each ratio twice: over the sub-trajectories both settings *finished* (the targets' "
        "figure) and over *all*, a failed run's at the penalty "
        f"({_f(m['penalty_pct'], 0)} %). A sub-trajectory fails above {failures}. Over runs: "
        "geometric means, with scipy's BCa interval where a family has at least five runs. "
        "A fold's fixed set is the best trial of a joint study over its training units, a "
        "unit the trial failed on counted at the penalty (`fixed.failures: sequence`). "
        "The in-sample best (a joint study on the test run itself) is a bound, never a "
        "choice. Settings, spaces and budgets were frozen before any test fold ran "
        "(real/params.yaml; the params at the end); the one change since is that rule, made "
        "after NDT's first folds (where the old one, `trial`, left the joint studies of two "
        "folds with no finished trial) and before any other algorithm's (docs/design.md, "
        "\"The real-data study\")."]


def _targets(m: Mapping[str, Any]) -> list[str]:
    algorithms = m["algorithms"]
    rows = []
    for key, t in m["targets"].items():
        rows.append([TARGET_TITLES.get(key, key), f"<= {_f(t['at_most'], 2)}",
                     *(_f(t["per_algorithm"].get(a), 2) for a in algorithms),
                     "met" if t["met"] else "**not met**"])
    return ["## Targets", "", "Over the sub-trajectories both settings finished.", "",
            *_table(["figure", "goal", *algorithms, ""], rows)]


def _algorithm(algorithm: str, a: Mapping[str, Any]) -> list[str]:
    lines = [f"## {algorithm}", ""]
    for family, title in FAMILY_TITLES.items():
        runs = [r for r in a["runs"] if r["family"] == family]
        if not runs:
            continue
        lines += [f"### {title}", "", *_runs(runs), "", *_family(a["families"][family]), ""]
    lines += [*_cost(a["cost"])]
    return lines


def _ratio(r: Mapping[str, Any]) -> str:
    if r["value"] is None:
        return "-"
    if r["low"] is None or r["high"] is None:
        return _f(r["value"], 2)
    return f"{_f(r['value'], 2)} ({_f(r['low'], 2)}-{_f(r['high'], 2)})"


def _runs(runs: Sequence[Mapping[str, Any]]) -> list[str]:
    head = ["fold", "run", *(f"{TITLES[n]}: finished / all" for n in TITLES), "RTE [%] and "
            "failure rate: baseline, fixed, adaptive, in-sample", "floor [%], floor / fixed",
            "selector: fallback share, changes, k"]
    rows = []
    for r in runs:
        ratios = [f"{_ratio(r['ratios'][n]['finished'])} / {_f(r['ratios'][n]['all']['value'], 2)}"
                  if n in r["ratios"] else "-" for n in TITLES]
        pooled = ", ".join(f"{_f(p['rte_pct'], 1)} ({_pct(p['failure_rate'])})"
                           for p in r["pooled"].values())
        floor = f"{_f(r['floor']['rte_pct'], 2)}, {_f(r['floor'].get('floor_vs_fixed'), 2)}"
        sel = r["selector"]
        rows.append([r["fold"], r["run"], *ratios, pooled, floor,
                     f"{_pct(sel['novel_share'])}, {sel['changes']}, {r['k']}"])
    return _table(head, rows)


def _family(fam: Mapping[str, Any]) -> list[str]:
    rows = []
    for name, title in TITLES.items():
        f, a = fam[name]["finished"], fam[name]["all"]
        interval = ("no interval (fewer than 5 runs)" if f["low"] is None
                    else f"{_f(f['low'], 2)}-{_f(f['high'], 2)}")
        rows.append([title, _f(f["geomean"], 2), interval, _f(f["worst"], 2), f["runs"],
                     _f(a["geomean"], 2)])
    return ["Over the family's runs:", "",
            *_table(["ratio", "geometric mean (finished)", "95 % BCa", "worst run", "runs",
                     "geometric mean (all)"], rows)]


def _trials(c: Mapping[str, int]) -> str:
    parts = [f"{v} {k}" for k, v in c.items() if k != "all"]
    return f"{c.get('all', 0)}" + (f" ({', '.join(parts)})" if parts else "")


def _cost(cost: Mapping[str, Any]) -> list[str]:
    rows = [["every unit's own study", _trials(cost["unit_studies"]), "-", "-"]]
    for fold, c in cost.items():
        if fold == "unit_studies":
            continue
        trials = f"joint {_trials(c['joint_trials'])}; in-sample {_trials(c['in_sample_trials'])}"
        rows.append([f"fold {fold}", trials, c["suite_runs"], c["suite_frames"]])
    return ["### Cost", "", "Odometry runs, counted (the same on every machine; the wall "
            "times of a run are in docs/performance.md):", "",
            *_table(["step", "trials (by status)", "suite runs", "suite frames"], rows)]


def _units(m: Mapping[str, Any]) -> list[str]:
    rows = [[u["name"], u["run"], u["half"], u["frames"], _f(u["path_m"], 1),
             _f(u["start_m"], 1)] for u in m["units"]]
    halves = [[run, _f(h["closest_m"], 1), _pct(h["second_within_10m"]), _f(h["length_m"], 0)]
              for run, h in m["halves"].items()]
    return ["## The units", "",
            "Every run cut into two halves by distance (a run cut into pieces at its gaps: a "
            "unit per piece and half).", "",
            *_table(["unit", "run", "half", "frames", "path [m]", "starts at [m]"], rows), "",
            "How close each run's second half comes to its first, away from where they meet "
            "(positions more than L apart along the path): the in-distribution folds test on "
            "ground next to what they trained on.", "",
            *_table(["run", "closest [m]", "second-half frames within 10 m", "L [m]"], halves)]


def _figure(m: Mapping[str, Any]) -> list[str]:
    return ["## The frozen fold from above", "",
            f"Fold {m['plot_fold']}: every test unit's reference against the nominal runs of "
            "baseline, fixed and adaptive, each started at the reference's first pose.", "",
            f"![fold {m['plot_fold']} from above]({FIGURE})"]
