"""`adaptune select MODEL SEQ.mcap --out SCHEDULE.parquet`: the parameter schedule of a recorded
sequence (a selection every period_s from the newest scan, held in between)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import (
    model_run_options,
    params_option,
    refuse_json_on_stdout,
    report_selection,
)


@click.command()
@params_option
@model_run_options("The schedule: Parquet, or CSV when it ends in .csv (frame, stamp_ns, one "
                   "column per parameter).")
@click.option("--period-s", type=float, default=None,
              help="Override select.period_s of the params [s].")
def select(
    params_path: Path | None, model_dir: Path, sequence: Path, out: Path, algorithm: str | None,
    period_s: float | None, as_json: bool,
) -> None:
    """Parameter schedule of a recorded sequence from a model artifact (the selector's
    settings: params ``select``)."""
    from pipeline.config import SelectSection, load_section
    from pipeline.errors import ConfigError
    from pipeline.io_utils import refuse_input_as_output
    from pipeline.odometry.registry import declared_space
    from pipeline.runtime import Selector, load_model
    from pipeline.sequence import SequenceReader

    refuse_json_on_stdout(out, as_json)
    refuse_input_as_output(out, [sequence, params_path, *sorted(model_dir.glob("*"))])
    try:
        selection = load_section(params_path, "select", SelectSection).settings().replace(
            period_s=period_s)
    except ValueError as exc:  # --period-s out of range, named as its params key
        raise ConfigError(str(exc)) from None
    model = load_model(model_dir, expected_algorithm=algorithm,
                       declared_space=declared_space)
    selector = Selector(model, selection)
    with SequenceReader(sequence) as reader:
        schedule = selector.schedule(reader)
    schedule.write(out)
    report_selection({"algorithm": model.algorithm, "frames": len(schedule),
                      "selections": selector.selections, "changes": schedule.n_changes,
                      "out": str(out)}, as_json)
