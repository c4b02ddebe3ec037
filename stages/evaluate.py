"""``adaptune evaluate``: baseline vs fixed vs adaptive on the validation sequences (dvc stage).

Writes the figures for ``dvc metrics show`` (--metrics) and the rest of the summary (--record),
CSV files for ``dvc plots show`` and report/report.md with its PNG figures
(``pipeline.report.report`` documents them).
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option, sequences_option


@click.command()
@params_option
@sequences_option
@dir_option("--trials", "trials_dir", help="Per-sequence SMBO output.")
@dir_option("--fixed", "fixed_dir", help="Joint SMBO output.")
@dir_option("--adaptive", "adaptive_dir", help="Adaptive runs.")
@dir_option("--out", "runs_dir", help="Folder for the baseline and fixed trajectories.")
@file_option("--metrics", "metrics_path", help="Metrics JSON to write (the figures).")
@file_option("--record", "record_path",
             help="JSON to write with the rest: what ran, trial counts, wall times.")
@dir_option("--plots", "plots_dir", help="Folder for plot CSVs.")
@dir_option("--report", "report_dir", help="Folder for report.md and its figures.")
@dir_option("--model", "model_dir", required=False,
            help="The model artifact: its cross-validation, for the warning of a surrogate "
            "that errs by more than the spread it ranks [no such warning].")
def evaluate(params_path: Path | None, sequence_dir: Path, trials_dir: Path, fixed_dir: Path,
             adaptive_dir: Path, runs_dir: Path, metrics_path: Path, record_path: Path,
             plots_dir: Path, report_dir: Path, model_dir: Path | None) -> None:
    """Score baseline, fixed and adaptive parameters; write metrics, plots and the report."""
    from pipeline.config import load_section
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.report.report import EvaluationPaths, run_evaluation

    settings = load_section(params_path, "evaluate", EvaluateSection)
    paths = EvaluationPaths(sequence_dir, trials_dir, fixed_dir, adaptive_dir, runs_dir,
                            metrics_path, record_path, plots_dir, report_dir, model_dir)
    m = run_evaluation(paths, settings)
    rte, ratio = m["rte_pct"], m["ratio"]
    click.echo(f"{m['algorithm']}: RTE baseline {rte['baseline']:.3f} %, fixed "
               f"{rte['fixed']:.3f} %, adaptive {rte['adaptive']:.3f} % "
               f"(x{ratio['adaptive_vs_baseline']:.2f} of baseline, "
               f"x{ratio['adaptive_vs_fixed']:.2f} of fixed) -> {report_dir / 'report.md'}",
               err=True)
    for line in m["warning_text"]:
        click.echo(f"warning: {line}", err=True)
