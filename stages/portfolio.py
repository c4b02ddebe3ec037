"""``adaptune portfolio``: every member of the portfolio run on every training sequence (dvc
stage ``portfolio`` of the coverage model; ``pipeline.portfolio``)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option, sequences_option


@click.command()
@params_option
@sequences_option
@dir_option("--out", "out_dir", help="Output folder (results/portfolio).")
@dir_option("--fixed", "fixed_dir", required=False,
            help="The joint study's output, whose best set joins the portfolio "
                 "(portfolio.fixed).")
@click.option("--split", default=None,
              help="The index split to run on [default: trials.split], e.g. one sensor's "
                   "worlds of the tuning suite (adaptune tuning-suite).")
@file_option("--record", "record_path", required=False,
             help="Write the studies' counts and wall times here (records/<stage>.json: the "
                  "trials tables keep no time).")
def portfolio(params_path: Path | None, sequence_dir: Path, out_dir: Path,
              fixed_dir: Path | None, split: str | None, record_path: Path | None) -> None:
    """Run the portfolio's parameter sets on every training sequence into OUT."""
    from pipeline.config import BaseSection, load_section
    from pipeline.evaluate.runs import best_fixed_params
    from pipeline.portfolio import PortfolioSection, run_portfolio
    from pipeline.sequence_index import read_index
    from pipeline.tuning.smbo import TrialsSection

    settings = load_section(params_path, "trials", TrialsSection)
    section = load_section(params_path, "portfolio", PortfolioSection)
    seed = load_section(params_path, "base", BaseSection).seed
    fixed = (best_fixed_params(fixed_dir, settings.algorithm)[1]
             if fixed_dir is not None and section.fixed else None)
    paths = read_index(sequence_dir).paths(split or settings.split)
    studies = run_portfolio(paths, out_dir, settings, section, seed, fixed)
    if record_path is not None:
        from pipeline.report.outputs import write_json

        write_json(record_path, {"studies": [s.record() for s in studies]})
    for s in studies:
        click.echo(f"{s.algorithm} {s.sequence}: {s.trials} sets ({s.ran} run now), "
                   f"{s.failed} failed, best {s.best_objective:.4g} % (set {s.best_trial})",
                   err=True)
