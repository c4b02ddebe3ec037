"""``adaptune adaptive``: adaptive runs on the evaluated sequences (dvc stage ``adaptive``).

The model picks the parameters of every period from the scans, the model's odometry runs with
that schedule; ``pipeline.adaptive`` documents the outputs. Untuned adapter settings come from
the params section ``trials`` (the runs must match the trials), the selector's runtime settings
from ``select``.
"""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, file_option, params_option, sequences_option


@click.command()
@params_option
@dir_option("--model", "model_dir", help="The artifact (model/).")
@sequences_option
@click.option("--split", "splits", multiple=True,
              help="Split of index.json to run, repeatable [evaluate.splits].")
@dir_option("--out", "out_dir",
            help="Output folder: <sequence>/{schedule,trajectory}.parquet and run.json.")
@file_option("--record", "record_path", required=False,
             help="Write every run's counts and wall times here (records/adaptive.json).")
def adaptive(params_path: Path | None, model_dir: Path, sequence_dir: Path, splits: tuple[str, ...],
             out_dir: Path, record_path: Path | None) -> None:
    """Schedule every sequence of the evaluated splits with the model and run its odometry."""
    from pipeline.adaptive import run_adaptive
    from pipeline.config import SelectSection, load_section
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.sequence_index import read_index
    from pipeline.tuning.smbo import TrialsSection

    trials = load_section(params_path, "trials", TrialsSection)
    section = load_section(params_path, "evaluate", EvaluateSection)
    selection = load_section(params_path, "select", SelectSection).settings()
    paths = list(read_index(sequence_dir).split_paths(list(splits) or section.splits))
    runs = run_adaptive(model_dir, paths, out_dir, trials.adapter_options,
                        workers=section.workers, selection=selection)
    if record_path is not None:
        from pipeline.report.outputs import write_json

        write_json(record_path, {"runs": [run.record() for run in runs]})
    for run in runs:
        click.echo(f"{run.sequence}: {run.frames} frames, {run.selections} selections, "
                   f"{run.changes} parameter changes, {run.wall_time_s:.1f} s", err=True)
