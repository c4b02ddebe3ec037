"""The ``verdict`` stage (one family's suite scored and summarised: ``run_verdict``) and the
``headroom`` stage (the oracles and the closed gap: ``run_headroom_study``); each reads like its
table of contents.

Check what was frozen (the world generator, the baseline, the fixed study's budget), take the
fixed parameters from the joint study, draw the suite's worlds, run baseline, fixed and
adaptive on each with their replicas (``studies.suites.runner``), then write the metrics JSON
(``studies.verdict.summary``), the plot data (one row per world) and the figure (one dot per
world and ratio, the geometric mean, its interval and the targets).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ConfigError, InputError
from pipeline.selection import SelectionSettings
from pipeline.sim.simulate import SimSpec
from studies.suites.runner import AdaptiveSetting, SuiteInputs, WorldResult
from studies.verdict.section import VerdictSection
from studies.verdict.summary import RATIOS


@dataclass(frozen=True)
class VerdictPaths:
    """Inputs and outputs of one ``verdict`` stage (all from verdict/dvc.yaml)."""

    model: Path  # model/ (the artifact)
    fixed: Path  # results/fixed (the joint study)
    runs: Path  # results/suites/<family>: every world's runs
    metrics: Path  # metrics/<family>.json
    plot_data: Path  # plots/<family>.csv
    figure: Path  # report/<family>.png


@dataclass(frozen=True)
class RunSettings:
    """What the stage takes from the other params sections: the failure penalty [%]
    (``trials``), the candidate grid of the portfolio and the oracles (``portfolio``), the
    joint study's budget (``fixed``), the selector (``select``) and the sensor settings of
    the training data (``simulate``: a template spec). The adapter's
    untuned options are the joint study's (its fingerprint)."""

    penalty_pct: float
    grid: dict[str, list[float]]
    fixed_iterations: int
    fixed_warm_start: int
    selection: SelectionSettings
    template: SimSpec


def load_settings(params_path: Path | None) -> tuple[VerdictSection, RunSettings]:
    """The ``verdict`` section of the params file and what the stages take from the others."""
    from pipeline.config import BaseSection, SelectSection, load_section
    from pipeline.portfolio import PortfolioSection
    from pipeline.sim.dataset import SimulateSection
    from pipeline.tuning.section import FixedSection, TrialsSection, joint_settings
    from studies.verdict.worlds import sensor_template

    section = load_section(params_path, "verdict", VerdictSection)
    trials = load_section(params_path, "trials", TrialsSection)
    fixed = load_section(params_path, "fixed", FixedSection)
    base = load_section(params_path, "base", BaseSection)
    simulate = load_section(params_path, "simulate", SimulateSection)
    selection = load_section(params_path, "select", SelectSection).settings()
    iterations = joint_settings(trials, fixed).iterations
    grid = load_section(params_path, "portfolio", PortfolioSection).grid
    return section, RunSettings(trials.penalty_pct, grid, iterations,
                                fixed.warm_start, selection, sensor_template(simulate, base.seed))


def run_verdict(paths: VerdictPaths, family: str, section: VerdictSection,
                settings: RunSettings) -> dict[str, Any]:
    """Score ``family``'s suite ``section.suite`` (module docstring); return the metrics."""
    from pipeline.io_utils import atomic_write_text
    from pipeline.outputs import csv_text, write_json
    from studies.suites.runner import run_suite
    from studies.verdict.summary import plot_rows, suite_metrics
    from studies.verdict.worlds import suite_worlds

    worlds = suite_worlds(section, family, settings.template)
    inputs, study = suite_inputs(paths.model, paths.fixed, section, settings)
    results = run_suite(worlds, inputs, paths.runs, section.workers)
    header = {"algorithm": inputs.algorithm, "family": family, "suite": section.suite,
              "seed_root": section.root(family), "world_generator": section.world_generator,
              "length_m": section.length_m, "replicas": section.replicas,
              "replica_scale": section.replica_scale, "penalty_pct": settings.penalty_pct,
              "baseline": inputs.baseline, "fixed": inputs.fixed, "fixed_study": study,
              "select": settings.selection.to_json()}
    metrics = suite_metrics(results, header, section.failure_pct, section.confidence,
                            section.resamples, section.root(family), targets=section.targets)
    write_json(paths.metrics, metrics)
    atomic_write_text(paths.plot_data, csv_text(plot_rows(results)))
    suite_figure(results, metrics, paths.figure)
    return metrics


def run_oracles(fixed_dir: Path, runs_dir: Path, section: VerdictSection,
                settings: RunSettings) -> list[WorldResult]:
    """The oracles' runs on every world of the in-distribution suite ``section.suite``
    (``studies.verdict.headroom.run_headroom``) into ``runs_dir``, SBS from the joint study in
    ``fixed_dir``. They do not depend on the selector, so a new selector re-scores the headroom
    (``score_headroom``) without running them again."""
    from studies.verdict.headroom import candidate_set, run_headroom
    from studies.verdict.worlds import suite_worlds

    worlds = suite_worlds(section, "id", settings.template)
    inputs, _ = suite_inputs(None, fixed_dir, section, settings)
    candidates = candidate_set(settings.grid, inputs.baseline, inputs.fixed, inputs.space)
    return run_headroom(worlds, inputs, candidates, settings.selection.period_s, runs_dir,
                        section.workers)[1]


@dataclass(frozen=True)
class HeadroomPaths:
    """Inputs and outputs of the ``headroom`` stage (verdict/dvc.yaml)."""

    fixed: Path  # results/fixed (the joint study: SBS)
    oracles: Path  # results/headroom: every world's oracle runs (the oracles stage's output)
    suite: Path  # results/suites/id (SBS and adaptive per world)
    metrics: Path  # metrics/headroom.json
    figure: Path  # report/headroom.png


def score_headroom(paths: HeadroomPaths, section: VerdictSection,
                   settings: RunSettings) -> dict[str, Any]:
    """The oracles against SBS and the closed gap of the suite's adaptive, from the oracles'
    runs (``run_oracles``) and the suite's; write the metrics and the figure, return the
    metrics."""
    from pipeline.outputs import write_json
    from studies.suites.runner import read_results
    from studies.verdict.headroom import candidate_set, headroom_metrics
    from studies.verdict.worlds import suite_worlds

    inputs, study = suite_inputs(None, paths.fixed, section, settings)
    candidates = candidate_set(settings.grid, inputs.baseline, inputs.fixed, inputs.space)
    by_name = {r.name: r for r in read_results(paths.oracles)}
    names = [w.name for w in suite_worlds(section, "id", settings.template)]
    missing = [n for n in names if n not in by_name]
    if missing:
        raise InputError(f"{paths.oracles}: no oracle runs of the worlds {missing[:3]}"
                         f"{' ...' if len(missing) > 3 else ''} (run the oracles stage with "
                         "the same verdict section first)")
    oracles = [by_name[n] for n in names]  # the suite's order: the bootstrap's
    header = {"algorithm": inputs.algorithm, "family": "id", "suite": section.suite,
              "seed_root": section.root("id"), "world_generator": section.world_generator,
              "replicas": section.replicas, "baseline": inputs.baseline,
              "fixed": inputs.fixed, "fixed_study": study, "confidence": section.confidence}
    suite = read_results(paths.suite)
    metrics = headroom_metrics(suite, oracles, candidates, header, section.confidence,
                               section.resamples, section.root("id"),
                               section.closed_gap_target)
    write_json(paths.metrics, metrics)
    headroom_figure(suite, oracles, metrics, paths.figure)
    return metrics


def headroom_figure(suite: Sequence[WorldResult], oracles: Sequence[WorldResult],
                    metrics: Mapping[str, Any], out_png: Path) -> Path:
    """A dot per world of adaptive, the cross-fitted and the class oracle against SBS (log
    scale), each with its geometric mean and interval."""
    from pipeline.outputs import figure

    by_name = {r.name: r for r in suite}
    x = np.arange(len(oracles))
    sbs = np.array([by_name[o.name].median("fixed") for o in oracles])
    series = {"adaptive_vs_sbs": ([by_name[o.name].median("adaptive") for o in oracles],
                                  "tab:red"),
              "oracle_vs_sbs": ([o.median("oracle") for o in oracles], "tab:green"),
              "class_oracle_vs_sbs": ([o.median("class_oracle") for o in oracles], "tab:blue")}
    with figure(out_png, 1, 1, (max(8.0, 0.22 * len(oracles) + 3), 4.5)) as (fig, ax):
        a = ax[0, 0]
        for j, (name, (values, colour)) in enumerate(series.items()):
            s = metrics["ratios"][name]
            a.scatter(x + (j - 1) * 0.2, np.asarray(values) / sbs, s=16, color=colour,
                      label=f"{name.replace('_vs_sbs', '')}: {_fmt(s['geomean'])} "
                            f"({_fmt(s['low'])}-{_fmt(s['high'])})")
            if s["low"] is not None and s["high"] is not None:
                a.axhspan(s["low"], s["high"], color=colour, alpha=0.12)
        a.axhline(1.0, color="black", lw=0.8)
        a.set_yscale("log")
        a.set_ylabel("RTE / SBS (the fixed set)")
        a.set_xticks(x, [o.name.rsplit("_", 1)[-1] for o in oracles], fontsize=6)
        a.legend(fontsize=7, loc="upper left")
        gap = metrics["closed_gap"]["oracle"]
        fig.suptitle(f"headroom of the {metrics['family']} {metrics['suite']} suite: closed gap "
                     f"{_fmt(gap['value'])} ({_fmt(gap['low'])}-{_fmt(gap['high'])})")
    return out_png


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def suite_inputs(model: Path | None, fixed_dir: Path, section: VerdictSection,
                 settings: RunSettings) -> tuple[SuiteInputs, dict[str, int]]:
    """The suite's inputs after checking what was frozen: the baseline (the joint study's
    stored defaults) and the fixed study's budget; with the joint study's trial counts."""
    from pipeline.evaluate.runs import best_fixed_params
    from pipeline.tuning.table import read_adapter_options, read_space

    algorithm, fixed = best_fixed_params(fixed_dir)
    space = read_space(fixed_dir, algorithm)
    baseline = space.defaults()
    if baseline != section.baseline:
        raise InputError(f"{fixed_dir}: the studies' baseline {baseline} is not the frozen "
                         f"verdict.baseline {section.baseline}")
    if settings.fixed_iterations < section.fixed_trials or \
            settings.fixed_warm_start < section.fixed_warm_start:
        raise ConfigError(
            f"fixed: the joint study's budget is frozen at >= {section.fixed_trials} trials "
            f"warm-started from >= {section.fixed_warm_start} sets, got (iterations="
            f"{settings.fixed_iterations}, warm_start={settings.fixed_warm_start})")
    study = joint_study_counts(fixed_dir, algorithm)
    if study["trials"] < section.fixed_trials:
        raise InputError(f"{fixed_dir}: the joint study ran {study['trials']} trials, the "
                         f"frozen budget is {section.fixed_trials} (run the fixed stage)")
    adaptive = {} if model is None else {
        "adaptive": AdaptiveSetting(model, settings.selection, section.borrow_model)}
    for setting in adaptive.values():
        setting.check()
    inputs = SuiteInputs(algorithm, space, baseline, fixed,
                         read_adapter_options(fixed_dir, algorithm),
                         section.length_m, section.replicas, section.replica_scale,
                         settings.penalty_pct, adaptive)
    return inputs, study


def joint_study_counts(fixed_dir: Path, algorithm: str) -> dict[str, int]:
    """Trials of the joint study by status (``trials``: all of them)."""
    from pipeline.tuning.layout import JOINT_SEQUENCE, read_trials_tables

    rows = [r for r in read_trials_tables(fixed_dir).to_pylist()
            if r["sequence"] == JOINT_SEQUENCE and r["algorithm"] == algorithm]
    out = {"trials": len(rows)}
    for status in ("ok", "pruned", "failed"):
        out[status] = sum(r["status"] == status for r in rows)
    return out


def suite_figure(results: Sequence[WorldResult], metrics: Mapping[str, Any],
                 out_png: Path) -> Path:
    """One panel per ratio: a dot per world (log scale, by sensor), the geometric mean, its
    interval (band) and the family's targets."""
    from pipeline.outputs import figure

    markers = {"hdl32": "o", "hdl64": "s", "vlp16": "^"}
    x = np.arange(len(results))
    with figure(out_png, len(RATIOS), 1, (max(8.0, 0.22 * len(results) + 3), 8),
                sharex=True) as (fig, ax):
        for row, (name, (den,)) in enumerate(RATIOS.items()):
            a = ax[row, 0]
            r = np.array([w.ratio("adaptive", den) for w in results])
            for sensor, marker in markers.items():
                mine = np.array([w.sensor == sensor for w in results])
                if mine.any():
                    a.scatter(x[mine], r[mine], marker=marker, s=22, label=sensor,
                              c=np.where(r[mine] < 1, "tab:green", "tab:red"))
            s = metrics["ratios"][name]
            if s["geomean"] is not None:
                a.axhline(s["geomean"], color="tab:blue", label=f"geometric mean "
                          f"{s['geomean']:.2f}")
            if s["low"] is not None and s["high"] is not None:
                a.axhspan(s["low"], s["high"], color="tab:blue", alpha=0.15,
                          label=f"{100 * metrics['confidence']:.0f} % interval "
                                f"{s['low']:.2f}-{s['high']:.2f}")
            a.axhline(1.0, color="black", lw=0.8)
            target = metrics["targets"].get(name)
            for value in () if target is None else (target["geomean_at_most"],
                                                     target["upper_end"][1]):
                a.axhline(value, color="tab:purple", ls=":", lw=1.0)
            a.set_yscale("log")
            a.set_ylabel(name.replace("_vs_", " / ").replace("best", "min(b, f)"))
            a.legend(fontsize=7, loc="upper left", ncols=3)
        ax[-1, 0].set_xticks(x, [w.name.rsplit("_", 1)[-1] for w in results], fontsize=6)
        ax[-1, 0].set_xlabel("world (median over runs; dotted: the targets)")
        fig.suptitle(f"{metrics['algorithm']} on the {metrics['family']} {metrics['suite']} "
                     f"suite: {metrics['worlds']} worlds, {metrics['replicas'] + 1} runs a "
                     f"setting")
    return out_png
