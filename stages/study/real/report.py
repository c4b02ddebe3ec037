"""``adaptune study real-report``: the real-data study's figures, every algorithm and fold, the
reference's floor beside them (real/dvc.yaml stage; ``studies.real.report``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option


@click.command("real-report")
@params_option
@dir_option("--units", "units_dir", help="The units (real-units).")
@dir_option("--results", "results_dir", help="Folder of <algorithm>/folds (real-folds).")
@file_option("--metrics", "metrics_path", help="Metrics JSON to write.")
@file_option("--plots", "plots_path", help="Plot CSV to write (a row per algorithm, fold, run).")
@file_option("--figure", "figure_path", help="PNG to write (the plotted fold from above).")
def real_report(params_path: Path, units_dir: Path, results_dir: Path, metrics_path: Path,
                plots_path: Path, figure_path: Path) -> None:
    """The figures of every algorithm and fold, the reference's floor beside them."""
    from studies.real.report import ReportPaths, run_report
    from studies.real.settings import load_settings

    settings = load_settings(params_path)
    m = run_report(ReportPaths(units_dir, results_dir, metrics_path, plots_path, figure_path),
                   settings)
    for algorithm, a in m["by_algorithm"].items():
        fam = a["families"].get("in_distribution", {}).get("adaptive_vs_fixed", {})
        value = fam.get("finished", {}).get("geomean")
        click.echo(f"{algorithm}: adaptive / fixed in distribution "
                   f"{'n/a' if value is None else f'{value:.2f}'}", err=True)
    click.echo(f"-> {metrics_path}", err=True)
