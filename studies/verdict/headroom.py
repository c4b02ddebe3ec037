"""The headroom of the in-distribution suite, in the suite's units (docs/results/verdict.md,
"Headroom"): how much better than the single best set any choice of parameters per world and
environment can do, and which share of that gap adaptive closes.

- **SBS**, the single best set: the joint study's fixed parameters (its runs are the suite's).
- **Cross-fitted oracle**: on every world, for every environment label, the best set of the
  frozen candidate set (``portfolio.grid``, the baseline and the fixed set), chosen by
  the mean RTE of that label's sub-trajectories on a replica the suite never runs (replica
  R + 1), then scored by really running the stitched schedule on the suite's replicas 0..R (the
  label at each selection holds for ``select.period_s``, as the selector's choice does; the
  switches are paid): what a selector that knew the environment and the world's best set for it
  could do, without the luck of choosing and scoring on the same run.
- **Class oracle**: per label, the candidate that was best on the *other* worlds of the suite
  (the mean over them of the log ratio to each world's median candidate, from their selection
  replica), run the same way: what carries over from one world to the next when the environment
  is known.
- **Closed gap** (ASlib): log(SBS / adaptive) / log(SBS / oracle) over the suite's geometric
  means, with its paired bootstrap interval (``studies.suites.statistics.closed_gap``).

Two passes over the worlds (``workers`` at a time): the first simulates every world, runs every
candidate on the selection replica and the cross-fitted oracle on the suite's replicas; the
second, which needs every world's candidates, simulates them again and runs the class oracle.
Each world's passes are kept as they finish (``studies.suites.journal``): a stopped run resumes
at the worlds it had not finished.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import InputError
from pipeline.odometry.base import Schedule, grid_sets
from studies.suites.runner import SuiteInputs, WorldResult
from studies.suites.statistics import closed_gap
from studies.suites.worlds import SimulatedWorld

log = logging.getLogger(__name__)
PROGRESS = logging.getLogger("pipeline.progress")

Params = dict[str, float]
ORACLES = ("oracle", "class_oracle")


def candidate_set(grid: Mapping[str, Sequence[float]], baseline: Params, fixed: Params,
                  space: Any) -> list[Params]:
    """The frozen grid's product, the baseline and the fixed set (validated against the
    studies' space; duplicates once, in that order)."""
    names = list(space.names)
    if set(grid) != set(names):
        raise InputError(f"portfolio.grid: the grid's parameters {sorted(grid)} are not the "
                         f"studies' {sorted(names)}")
    return space.distinct([*grid_sets({n: grid[n] for n in names}), baseline, fixed])


def held_schedule(labels: Sequence[str], stamps_ns: NDArray[np.int64],
                  choice: Mapping[str, Params], default: Params, period_s: float) -> Schedule:
    """A schedule that gives every frame the set ``choice`` names for the label of the last
    selection frame (a selection every ``period_s`` from the first frame, as
    ``Selector.due`` times them); a label without a choice gets ``default``."""
    names = list(default)
    values = np.empty((len(labels), len(names)))
    last: int | None = None
    current = default
    for i, stamp in enumerate(stamps_ns):
        if last is None or stamp - last >= period_s * 1e9 - 1e6:
            last = int(stamp)
            current = choice.get(labels[i], default)
        values[i] = [current[n] for n in names]
    return Schedule(np.arange(len(labels), dtype=np.int32),
                    {n: values[:, j].copy() for j, n in enumerate(names)},
                    np.asarray(stamps_ns, np.int64))


@dataclass
class CandidateRuns:
    """The first pass on one world: the mean RTE [%] of every candidate (by index) per label
    on the selection replica, the cross-fitted oracle's choice per label and its runs."""

    name: str
    label_rte: dict[str, list[float]]
    choice: dict[str, int]
    oracle: WorldResult


def label_means(t_err: NDArray[np.float64], labels: Sequence[str]) -> dict[str, float]:
    """Mean RTE [%] of the sub-trajectories starting in each label (NaN without any)."""
    lab = np.asarray(labels)
    out = {}
    for name in dict.fromkeys(labels):
        v = t_err[(lab == name) & np.isfinite(t_err)]
        out[name] = float(v.mean()) if len(v) else math.nan
    return out


def best_per_label(label_rte: Mapping[str, Sequence[float]]) -> dict[str, int]:
    """Per label, the index of the candidate with the lowest mean RTE (ties: the first)."""
    return {lab: int(np.nanargmin(np.where(np.isfinite(v), v, np.inf)))
            for lab, v in label_rte.items() if np.isfinite(v).any()}


def least_log_ratio(rte_pct: Sequence[ArrayLike]) -> int | None:
    """The candidate with the lowest mean, over ``rte_pct`` (each (C,): one world's or one
    sequence's RTE [%] of every candidate), of the log ratio to that vector's median candidate,
    so that no single hard world or failure rules the choice; a vector with a non-finite or
    non-positive entry is left out; None when none is left."""
    scores = [np.log(v / np.median(v)) for v in (np.asarray(r, np.float64) for r in rte_pct)
              if np.isfinite(v).all() and (v > 0).all()]
    return int(np.argmin(np.mean(scores, axis=0))) if scores else None


def class_choice(name: str,
                 label_rte: Mapping[str, Mapping[str, Sequence[float]]]) -> dict[str, int]:
    """Per label of world ``name``: the candidate best on the other worlds with that label
    (``least_log_ratio``); ``label_rte``: world name -> label -> (C,) RTE [%] of every
    candidate (``CandidateRuns.label_rte``)."""
    out = {}
    for lab in label_rte[name]:
        best = least_log_ratio([rte[lab] for other, rte in label_rte.items()
                                if other != name and lab in rte])
        if best is not None:
            out[lab] = best
    return out


def first_pass(world: SimulatedWorld, inputs: SuiteInputs, candidates: list[Params],
               period_s: float) -> CandidateRuns:
    """Every candidate on the selection replica, then the cross-fitted oracle on the suite's."""
    from studies.suites.runner import load_world

    t0 = time.perf_counter()
    loaded = load_world(world, inputs)
    selection_replica = inputs.replicas + 1
    per_label = [label_means(loaded.run(c, selection_replica, inputs.replica_scale)[0],
                             loaded.labels) for c in candidates]
    label_rte = {lab: [m[lab] for m in per_label] for lab in per_label[0]}
    choice = best_per_label(label_rte)
    oracle = _oracle_runs(world, loaded, inputs, "oracle", choice, candidates, period_s, t0)
    return CandidateRuns(world.name, label_rte, choice, oracle)


def second_pass(world: SimulatedWorld, inputs: SuiteInputs, candidates: list[Params],
                choice: dict[str, int], period_s: float) -> WorldResult:
    """The class oracle's runs on the suite's replicas."""
    from studies.suites.runner import load_world

    t0 = time.perf_counter()
    loaded = load_world(world, inputs)
    return _oracle_runs(world, loaded, inputs, "class_oracle", choice, candidates, period_s, t0)


def _oracle_runs(world: SimulatedWorld, loaded: Any, inputs: SuiteInputs, setting: str,
                 choice: Mapping[str, int], candidates: list[Params], period_s: float,
                 t0: float) -> WorldResult:
    schedule = held_schedule(loaded.labels, loaded.stamps_ns,
                             {lab: candidates[c] for lab, c in choice.items()}, inputs.fixed,
                             period_s)
    runs = [loaded.run(schedule, r, inputs.replica_scale) for r in range(inputs.replicas + 1)]
    chosen = {lab: candidates[c] for lab, c in choice.items()}
    return WorldResult(world.name, world.family, world.segments, world.sensor,
                       world.frames, world.seed, loaded.labels,
                       {setting: np.stack([t for t, _ in runs])},
                       {setting: [f for _, f in runs]},
                       {setting: {"changes": schedule.n_changes, "choice": chosen}},  # type: ignore[dict-item]
                       time.perf_counter() - t0)


def run_headroom(worlds: Sequence[SimulatedWorld], inputs: SuiteInputs,
                 candidates: list[Params], period_s: float, out_dir: Path,
                 workers: int) -> tuple[list[CandidateRuns], list[WorldResult]]:
    """Both passes over ``worlds`` (module docstring), the costliest worlds started first;
    ``out_dir`` written atomically: every world's oracle runs (``<world>/rte.parquet`` and
    ``world.json``, as the suite's). Each world's passes are kept as they finish in a journal
    beside ``out_dir`` (``studies.suites.journal``), so that a stopped run resumes."""
    from pipeline.io_utils import atomic_dir, atomic_write_text
    from studies.suites.journal import Journal, fingerprint
    from studies.suites.runner import write_runs

    PROGRESS.info("headroom: %d worlds, %d candidates", len(worlds), len(candidates))
    journal = Journal.open(out_dir, fingerprint((list(worlds), inputs, candidates, period_s)))
    t0 = time.monotonic()
    names, costs = [w.name for w in worlds], [w.cost for w in worlds]
    first = journal.run(
        "cross_fitted", first_pass, [(w, inputs, candidates, period_s) for w in worlds], names,
        workers, costs=costs,
        keep=lambda r: (r.oracle, {"label_rte": r.label_rte, "choice": r.choice}),
        restore=lambda oracle, extra: CandidateRuns(oracle.name, extra["label_rte"],
                                                    extra["choice"], oracle),
        on_done=lambda r, k: _pass_logged("cross-fitted", r.oracle, k, len(worlds), t0))
    label_rte = {r.name: r.label_rte for r in first}
    second = journal.run(
        "class", second_pass, [(w, inputs, candidates, class_choice(w.name, label_rte),
                                period_s) for w in worlds], names, workers, costs=costs,
        keep=lambda r: (r, None), restore=lambda r, _: r,
        on_done=lambda r, k: _pass_logged("class", r, k, len(worlds), t0))
    merged = []
    with atomic_dir(out_dir) as tmp:
        for a, b in zip(first, second, strict=True):
            both = a.oracle
            both.t_err_pct.update(b.t_err_pct)
            both.failed.update(b.failed)
            both.selection.update(b.selection)
            both.wall_time_s += b.wall_time_s
            write_runs(tmp / both.name, both)
            atomic_write_text(tmp / both.name / "candidates.json", json.dumps(
                {"candidates": candidates, "selection_replica_rte_pct": a.label_rte,
                 "choice": a.choice}, indent=2) + "\n")
            merged.append(both)
    journal.close()
    return first, merged


def _pass_logged(what: str, r: WorldResult, finished: int, n: int, t0: float) -> Any:
    """A progress line for the ``finished``-th world of ``n`` to finish a pass."""
    setting = next(iter(r.t_err_pct))
    PROGRESS.info("[%d/%d] %s %s oracle %.3f %%; %.0f s (%.0f s in all)", finished, n, r.name,
                  what, r.median(setting), r.wall_time_s, time.monotonic() - t0)
    return r


def headroom_metrics(suite: Sequence[WorldResult], oracles: Sequence[WorldResult],
                     candidates: list[Params],
                     header: Mapping[str, Any], confidence: float, resamples: int,
                     seed: int, closed_gap_target: float) -> dict[str, Any]:
    """The JSON of the headroom study: every oracle and adaptive against SBS, the closed gaps
    and their target (params ``verdict.closed_gap_target``), every world."""
    from studies.verdict.summary import ratio_summary

    by_name = {r.name: r for r in suite}
    missing = [o.name for o in oracles if o.name not in by_name]
    if missing:
        raise InputError(f"the suite's results lack the worlds {missing}: run the suite with "
                         f"the same verdict section first")
    sbs = np.array([by_name[o.name].median("fixed") for o in oracles])
    adaptive = np.array([by_name[o.name].median("adaptive") for o in oracles])
    medians = {k: np.array([o.median(k) for o in oracles]) for k in ORACLES}
    ratios = {"adaptive_vs_sbs": ratio_summary(adaptive / sbs, confidence, resamples, seed)}
    gaps = {}
    for k in ORACLES:
        ratios[f"{k}_vs_sbs"] = ratio_summary(medians[k] / sbs, confidence, resamples, seed)
        gaps[k] = closed_gap(np.log(sbs / adaptive), np.log(sbs / medians[k]), confidence,
                             resamples, seed).to_json()
    headroom = ratios["oracle_vs_sbs"]
    gap = gaps["oracle"]
    return {
        **header,
        "worlds": len(oracles),
        "candidates": candidates,
        "ratios": ratios,
        "closed_gap": gaps,
        "headroom": headroom["high"] is not None and headroom["high"] < 1.0,
        "targets": {"closed_gap": {"at_least": closed_gap_target, "low_above": 0.0,
                                   "met": bool(gap["value"] is not None
                                               and gap["value"] >= closed_gap_target
                                               and gap["low"] is not None and gap["low"] > 0)}},
        "per_world": {o.name: {"sbs_rte_pct": float(s), "adaptive_rte_pct": float(a),
                               **{f"{k}_rte_pct": float(medians[k][i]) for k in ORACLES},
                               "choice": {k: o.selection[k]["choice"] for k in ORACLES}}
                      for i, (o, s, a) in enumerate(zip(oracles, sbs, adaptive, strict=True))},
    }
