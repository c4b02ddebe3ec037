"""`adaptune select MODEL SEQ.mcap --out SCHEDULE.parquet`: the parameter schedule of a recorded
sequence (a selection every period_s from the newest scan, held in between)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import model_run_options, report_selection


@click.command()
@model_run_options("The schedule Parquet (frame, stamp_ns, one column per parameter).")
@click.option("--period-s", type=float, default=None, help="Override the model's period [s].")
def select(
    model_dir: Path, sequence: Path, out: Path, algorithm: str | None, period_s: float | None,
    as_json: bool,
) -> None:
    """Parameter schedule of a recorded sequence from a model artifact."""
    from pipeline.io_utils import refuse_input_as_output
    from pipeline.runtime import Selector, load_model
    from pipeline.sequence import SequenceReader

    refuse_input_as_output(out, [sequence, *sorted(model_dir.glob("*"))])
    model = load_model(model_dir, expected_algorithm=algorithm)
    selector = Selector(model, period_s=period_s)
    with SequenceReader(sequence) as reader:
        schedule = selector.schedule(reader)
    schedule.write(out)
    report_selection({"algorithm": model.algorithm, "frames": len(schedule),
                      "selections": selector.selections, "changes": schedule.n_changes,
                      "out": str(out)}, as_json)
