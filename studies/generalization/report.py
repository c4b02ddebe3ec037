"""The ``generalize`` stage's outputs: ``run_generalization`` reads like its table of contents.

Take the fixed parameters from the joint SMBO, score baseline, fixed and adaptive on every
world of the suite (``studies.suites.runner``, seen as ``studies.generalization.score``), then
write the metrics JSON (the figures) and the record (the rest), the plot data (one row per
world) and the figure (RTE of every setting per world above, the ratio adaptive / min(baseline,
fixed) per world below, with the targets).

``generalize.worlds: 0`` runs no world: the stage then writes empty metrics, a record that says
so, plot data without rows and a figure that says so. An experiment that skips the suite (the
KITTI protocol: ``make kitti``) thus carries no figure of an earlier run's suite, as it would if
it stopped at the ``evaluate`` target (DVC keeps the outputs of the stages it does not run).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.io_utils import atomic_write_text
from pipeline.selection import SelectionSettings
from studies.generalization.score import WorldScore, world_score
from studies.generalization.suite import GeneralizeSection, generalization_worlds
from studies.generalization.summary import (
    PLOT_COLUMNS,
    RECORD_KEYS,
    generalization_metrics,
    generalization_rows,
)


@dataclass(frozen=True)
class GeneralizationPaths:
    """Inputs and outputs of the ``generalize`` stage (all from dvc.yaml)."""

    model: Path  # model/ (the artifact)
    fixed: Path  # results/fixed (joint SMBO)
    runs: Path  # results/generalization: trajectories and schedules per world
    metrics: Path  # metrics/generalization.json (the figures)
    record: Path  # records/generalization.json (the rest of the summary)
    plot_data: Path  # plots/generalization.csv
    figure: Path  # report/generalization.png


def run_generalization(paths: GeneralizationPaths, section: GeneralizeSection,
                       selection: SelectionSettings | None = None) -> dict[str, Any]:
    """Score the suite ``section.suite`` with the selector's runtime ``selection`` (params
    ``select``; None: the defaults); write metrics, record, plot data and figure; return the
    summary (metrics and record together)."""
    from pipeline.evaluate.runs import best_fixed_params
    from pipeline.outputs import csv_text, write_metrics
    from pipeline.tuning.table import read_adapter_options, read_space
    from studies.suites.runner import AdaptiveSetting, SuiteInputs, run_suite

    if section.worlds == 0:
        return no_suite(paths, section)

    algorithm, fixed = best_fixed_params(paths.fixed)
    space = read_space(paths.fixed, algorithm)
    adaptive = AdaptiveSetting(paths.model, selection or SelectionSettings())
    adaptive.check()
    options = read_adapter_options(paths.fixed, algorithm)  # as the studies ran
    inputs = SuiteInputs(algorithm, space, space.defaults(), fixed, options,
                         section.length_m, section.replicas, section.replica_scale,
                         penalty_pct=None, adaptive={"adaptive": adaptive},
                         keep_trajectories=True)
    results = run_suite(generalization_worlds(section), inputs, paths.runs, section.workers)
    scores = [world_score(r) for r in results]
    result = generalization_metrics(scores, section.suite, section.root, section.bootstrap,
                                    algorithm, section.length_m, section.targets.model_dump())
    write_metrics(paths.metrics, paths.record, result, RECORD_KEYS)
    atomic_write_text(paths.plot_data, csv_text(generalization_rows(scores)))
    generalization_figure(scores, result, paths.figure)
    return result


def no_suite(paths: GeneralizationPaths, section: GeneralizeSection) -> dict[str, Any]:
    """The outputs of a suite of no world (module docstring); returns its summary."""
    from pipeline.io_utils import atomic_dir
    from pipeline.outputs import csv_text, figure, write_metrics

    note = "generalize.worlds is 0: no world was run"
    summary: dict[str, Any] = {"suite": section.suite, "worlds": 0, "not_run": note}
    with atomic_dir(paths.runs) as tmp:
        (tmp / "not_run.txt").write_text(note + "\n", encoding="utf-8")
    write_metrics(paths.metrics, paths.record, summary, RECORD_KEYS)
    atomic_write_text(paths.plot_data, csv_text([], header=PLOT_COLUMNS))
    with figure(paths.figure, size=(6, 1.5)) as (_, ax):
        ax[0, 0].axis("off")
        ax[0, 0].text(0.5, 0.5, f"{section.suite} suite not run (generalize.worlds = 0)",
                      ha="center", va="center")
    return summary


def generalization_figure(scores: Sequence[WorldScore], metrics: Mapping[str, Any],
                          out_png: Path) -> Path:
    """RTE of every setting per world (top, log scale; with replicas a line over the range of
    its runs) and adaptive / min(baseline, fixed) per world (bottom, log scale; with replicas
    the ratio of the settings' medians as a diamond) with the median and the targets."""
    from pipeline.evaluate.result import SETTINGS
    from pipeline.outputs import SETTING_COLOURS, figure

    x = np.arange(len(scores))
    names = [f"{s.name}\n{'-'.join(lab[0] for lab in s.segments)} {s.sensor}" for s in scores]
    best = metrics["summary"]["adaptive_vs_best"]
    with figure(out_png, 2, 1, (max(8.0, 0.7 * len(scores) + 2), 7), sharex=True) as (fig, ax):
        for j, setting in enumerate(SETTINGS):
            ax[0, 0].bar(x + (j - 1) * 0.27, [s.rte_pct[setting] for s in scores], 0.27,
                         color=SETTING_COLOURS[setting], label=setting)
            if any(s.replicas_rte_pct for s in scores):  # the range of the setting's runs
                lo, hi = np.array([_range(s.runs(setting)) for s in scores]).T
                ax[0, 0].vlines(x + (j - 1) * 0.27, lo, hi, color="black", lw=1.0)
        ax[0, 0].set_yscale("log")
        ax[0, 0].set_ylabel(f"RTE over {metrics['length_m']:g} m [%]")
        ax[0, 0].legend(fontsize=8)
        ratio = [s.ratios()["adaptive_vs_best"] for s in scores]
        ax[1, 0].bar(x, ratio, 0.6, color=["tab:green" if r < 1 else "tab:red" for r in ratio])
        if any(s.replicas_rte_pct for s in scores):
            ax[1, 0].plot(x, [s.replica_ratios()["adaptive_vs_best"] for s in scores], "kD",
                          ms=5, label="ratio of the medians over the replicas")
        ax[1, 0].axhline(1.0, color="black", lw=0.8)
        if best["median"] is not None:
            ax[1, 0].axhline(best["median"], color="tab:blue", ls="-",
                             label=f"median {best['median']:.2f}")
        ax[1, 0].axhline(metrics["targets"]["median"], color="tab:blue", ls=":",
                         label="target median")
        ax[1, 0].axhline(metrics["targets"]["worst"], color="tab:red", ls=":",
                         label="target worst")
        ax[1, 0].set_yscale("log")
        ax[1, 0].set_ylabel("adaptive / min(baseline, fixed)")
        ax[1, 0].legend(fontsize=8)
        ax[1, 0].set_xticks(x, names, fontsize=7)
        fig.suptitle(f"{metrics['algorithm']} on the {metrics['suite']} suite "
                     f"({metrics['worlds']} unseen worlds; c/o/s: cave/open/street)")
    return out_png


def _range(values: Sequence[float]) -> tuple[float, float]:
    """(min, max) of the finite values (NaN, NaN without any)."""
    ok = [v for v in values if np.isfinite(v)]
    return (min(ok), max(ok)) if ok else (float("nan"), float("nan"))
