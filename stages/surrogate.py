"""`adaptune surrogate`: fit the surrogate from the results database, write model/."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from pipeline.config import load_section
from stages.common import algorithm_option, dir_option, file_option, params_option


@click.command()
@params_option
@file_option("--db", "db_path", help="results/adaptune.duckdb (surrogate_rows view).")
@dir_option("--pca", "pca_dir", help="The PCA folder written by `adaptune descriptors`.")
@dir_option("--out", help="The artifact folder (model/).")
@dir_option("--trials", "trials_dir", required=False,
            help="The trials output (results/trials), whose stored parameter space the model "
                 "uses [default: the adapter's built-in ranges].")
@algorithm_option("Algorithm of the rows (default: the only one).")
@file_option("--metrics", "metrics_path", required=False,
             help="Write the CV errors here (JSON; the figures).")
@file_option("--record", "record_path", required=False,
             help="Write the rest of the CV summary here (JSON: algorithm, folds, rows).")
def surrogate(
    params_path: Path | None,
    db_path: Path,
    pca_dir: Path,
    out: Path,
    trials_dir: Path | None,
    algorithm: str | None,
    metrics_path: Path | None,
    record_path: Path | None,
) -> None:
    """Fit the surrogate S(E, x) ~ y and write the deployable artifact."""
    from pipeline.descriptors.dataset import DescriptorsSection
    from pipeline.errors import ConfigError
    from pipeline.odometry.registry import get_adapter
    from pipeline.outputs import write_metrics
    from pipeline.surrogates.cross_validation import RECORD_KEYS
    from pipeline.surrogates.fit import ModelInputs, build_model
    from pipeline.surrogates.section import SurrogateSection
    from pipeline.tuning.section import TrialsSection
    from pipeline.tuning.table import read_adapter_options, read_space

    if (metrics_path is None) != (record_path is None):
        raise ConfigError("--metrics and --record go together (the CV figures and the rest)")
    section = load_section(params_path, "surrogate", SurrogateSection)
    descriptors = load_section(params_path, "descriptors", DescriptorsSection)
    # the space the studies searched and the options they ran with, stored with the trials
    # (without them: the adapter's built-in space, built with params trials.adapter_options)
    if trials_dir is not None:
        def space_of(name: str) -> Any:
            return read_space(trials_dir, name)

        def options_of(name: str) -> dict[str, Any]:
            return read_adapter_options(trials_dir, name)
    else:
        options = load_section(params_path, "trials", TrialsSection).adapter_options

        def space_of(name: str) -> Any:
            return get_adapter(name, **options).space

        def options_of(name: str) -> dict[str, Any]:
            return dict(options)
    manifest = build_model(ModelInputs(db_path, pca_dir), out, section, descriptors, space_of,
                           algorithm, options_of)
    algo, cv, training = manifest["algorithm"], manifest["cross_validation"], manifest["training"]
    if metrics_path is not None and record_path is not None:
        from pipeline.provenance import revision

        write_metrics(metrics_path, record_path,
                      {"algorithm": algo, **cv,
                       "provenance": revision(None, manifest["provenance"]["inputs"])},
                      (*RECORD_KEYS, "provenance"))
    click.echo(
        f"{algo}: {training['rows']} rows, {training['environments']} frames "
        f"-> {out}; LOSO CV MAE {cv['mae']}, RMSE {cv['rmse']}, regret {cv['regret_mean']}, "
        f"rank gap {cv['rank_gap_median']}",
        err=True,
    )
    from pipeline.report.checks import surrogate_error_exceeds_rank_gap

    if surrogate_error_exceeds_rank_gap(cv):
        click.echo("warning: the CV MAE exceeds the rank gap (the median RTE gap between the "
                   "best and the worst trial at a held-out frame): the surrogate's choices are "
                   "close to chance", err=True)
