"""``adaptune generalize``: baseline, fixed and adaptive on unseen worlds (dvc stage).

Simulates the worlds of the params section ``generalize`` (suite ``test`` by default, ``dev``
for development: ``dvc exp run -S generalize.suite=dev``), scores the three settings on each and
writes metrics/generalization.json (the figures), records/generalization.json (the rest), the
plot data and the figure (``studies.generalization`` documents them; ``-S generalize.worlds=0``
runs no world and writes outputs that say so).
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option


@click.command()
@params_option
@dir_option("--model", "model_dir", help="The artifact (model/).")
@dir_option("--fixed", "fixed_dir", help="Joint SMBO output (the fixed parameters).")
@dir_option("--out", "runs_dir", help="Folder for the trajectories and schedules per world.")
@file_option("--metrics", "metrics_path", help="Metrics JSON to write (the figures).")
@file_option("--record", "record_path",
             help="JSON to write with the rest: the worlds, wall times, replica runs.")
@file_option("--plots", "plots_path", help="Plot CSV to write (one row per world).")
@file_option("--figure", "figure_path", help="PNG to write.")
def generalize(params_path: Path, model_dir: Path, fixed_dir: Path, runs_dir: Path,
               metrics_path: Path, record_path: Path, plots_path: Path, figure_path: Path
               ) -> None:
    """Score baseline, fixed and adaptive on a suite of worlds the model never saw."""
    from pipeline.config import SelectSection, load_section
    from pipeline.tuning.smbo import TrialsSection
    from studies.generalization.report import GeneralizationPaths, run_generalization
    from studies.generalization.suite import GeneralizeSection

    section = load_section(params_path, "generalize", GeneralizeSection)
    trials = load_section(params_path, "trials", TrialsSection)
    selection = load_section(params_path, "select", SelectSection).settings()
    paths = GeneralizationPaths(model_dir, fixed_dir, runs_dir, metrics_path, record_path,
                                plots_path, figure_path)
    m = run_generalization(paths, section, trials.adapter_options, selection)
    if not m["worlds"]:
        click.echo(f"{m['suite']} suite: {m['not_run']} -> {metrics_path} holds no figure",
                   err=True)
        return
    best = m["summary"]["adaptive_vs_best"]
    lo, hi = best["median_interval"]
    click.echo(f"{m['algorithm']} on the {m['suite']} suite ({m['worlds']} worlds): "
               f"adaptive / min(baseline, fixed) median {best['median']:.2f} "
               f"(90 % interval {lo:.2f}-{hi:.2f}), worst {best['worst']:.2f} "
               f"({best['worst_world']}), win rate {100 * best['win_rate']:.0f} % "
               f"-> {metrics_path}", err=True)
