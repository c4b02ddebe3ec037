"""``adaptune verdict``, ``oracles``, ``headroom`` and ``tuning-suite``: the coverage model's
suites (verdict/dvc.yaml).

``verdict --family id|ood`` simulates the worlds of the family's suite (``verdict.suite``:
``test`` by default, ``dev`` where choices are made), runs baseline, fixed and adaptive on each
with their replicas and writes the metrics, the plot data and the figure; ``oracles`` runs the
oracle's candidate set and the oracles on the in-distribution suite (they do not depend on the
selector); ``headroom`` scores them and the suite's adaptive against SBS and writes the closed
gap; ``tuning-suite`` simulates the worlds the coverage model's portfolio is tuned on
(``studies.verdict`` documents them).
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option


@click.command()
@params_option
@click.option("--family", type=click.Choice(["id", "ood"]), required=True,
              help="In distribution (trained environments and sensors) or out of it.")
@dir_option("--model", "model_dir", help="The artifact (model/).")
@dir_option("--fixed", "fixed_dir", help="Joint SMBO output (the fixed parameters).")
@dir_option("--out", "runs_dir", help="Folder for every world's runs.")
@file_option("--metrics", "metrics_path", help="Metrics JSON to write.")
@file_option("--plots", "plots_path", help="Plot CSV to write (one row per world).")
@file_option("--figure", "figure_path", help="PNG to write.")
def verdict(params_path: Path, family: str, model_dir: Path, fixed_dir: Path, runs_dir: Path,
            metrics_path: Path, plots_path: Path, figure_path: Path) -> None:
    """Score baseline, fixed and adaptive on a family's suite of worlds never trained on."""
    from studies.verdict.report import VerdictPaths, load_settings, run_verdict

    section, settings = load_settings(params_path)
    paths = VerdictPaths(model_dir, fixed_dir, runs_dir, metrics_path, plots_path, figure_path)
    m = run_verdict(paths, family, section, settings)
    parts = []
    for name in ("adaptive_vs_fixed", "adaptive_vs_baseline"):
        r = m["ratios"][name]
        parts.append(f"{name.replace('_vs_', ' / ')} {_num(r['geomean'])} "
                     f"({_num(r['low'])}-{_num(r['high'])})")
    click.echo(f"{m['algorithm']} on the {family} {m['suite']} suite ({m['worlds']} worlds): "
               f"{'; '.join(parts)} -> {metrics_path}", err=True)


def _num(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


@click.command()
@params_option
@dir_option("--fixed", "fixed_dir", help="Joint SMBO output (SBS, the fixed parameters).")
@dir_option("--out", "runs_dir", help="Folder for every world's oracle runs.")
def oracles(params_path: Path, fixed_dir: Path, runs_dir: Path) -> None:
    """Run the oracles (cross-fitted and class) on every in-distribution world."""
    from studies.verdict.report import load_settings, run_oracles

    section, settings = load_settings(params_path)
    runs = run_oracles(fixed_dir, runs_dir, section, settings)
    click.echo(f"oracles on {len(runs)} worlds of the id {section.suite} suite -> {runs_dir}",
               err=True)


@click.command()
@params_option
@dir_option("--fixed", "fixed_dir", help="Joint SMBO output (SBS, the fixed parameters).")
@dir_option("--suite", "suite_dir", help="The in-distribution suite's runs (verdict --family id).")
@dir_option("--oracles", "runs_dir", help="The oracles' runs (adaptune oracles).")
@file_option("--metrics", "metrics_path", help="Metrics JSON to write.")
@file_option("--figure", "figure_path", help="PNG to write.")
def headroom(params_path: Path, fixed_dir: Path, suite_dir: Path, runs_dir: Path,
             metrics_path: Path, figure_path: Path) -> None:
    """The oracles of the in-distribution suite against SBS, and the gap adaptive closes."""
    from studies.verdict.report import HeadroomPaths, load_settings, score_headroom

    section, settings = load_settings(params_path)
    m = score_headroom(HeadroomPaths(fixed_dir, runs_dir, suite_dir, metrics_path,
                                     figure_path), section, settings)
    o, gap = m["ratios"]["oracle_vs_sbs"], m["closed_gap"]["oracle"]
    click.echo(f"{m['algorithm']} on the id {m['suite']} suite ({m['worlds']} worlds): "
               f"cross-fitted oracle / SBS {_num(o['geomean'])} ({_num(o['low'])}-"
               f"{_num(o['high'])}), closed gap {_num(gap['value'])} ({_num(gap['low'])}-"
               f"{_num(gap['high'])}) -> {metrics_path}", err=True)


@click.command("tuning-suite")
@params_option
@dir_option("--out", help="Folder for <name>.mcap and index.json (data/tune).")
def tuning_suite(params_path: Path, out: Path) -> None:
    """Simulate the coverage model's tuning suite (verdict.tuning), indexed per sensor."""
    from studies.verdict.report import load_settings
    from studies.verdict.tuning import simulate_tuning_suite, tuning_worlds

    section, settings = load_settings(params_path)
    worlds = simulate_tuning_suite(tuning_worlds(section, settings.template), out,
                                   section.workers, section.tuning.compression)
    for w in worlds:
        click.echo(f"{out / w.name}.mcap: {w.description}", err=True)
    click.echo(f"{out / 'index.json'}: {len(worlds)} worlds", err=True)
