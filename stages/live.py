"""`adaptune live MODEL SEQ.mcap --out OUT.mcap`: scans streamed one by one through the odometry,
parameters chosen online every period and pushed into it; the output MCAP holds the scans, the
ground truth, the anchored estimate (``/odometry/pose``, ``/tf``) and the parameters
(``/adaptune/params``, rcl_interfaces/msg/ParameterEvent), all ROS 2 types, for Foxglove
(``pipeline.live`` documents the channels and frames)."""

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
@model_run_options("Output MCAP (scans, ground truth, estimated poses, chosen parameters).")
def live(params_path: Path | None, model_dir: Path, sequence: Path, out: Path,
         algorithm: str | None, as_json: bool) -> None:
    """Stream a sequence through odometry with online parameter selection (the selector's
    settings: params ``select``)."""
    from pipeline.config import SelectSection, load_section
    from pipeline.io_utils import refuse_input_as_output
    from pipeline.live import run_live
    from pipeline.odometry.registry import declared_space
    from pipeline.runtime import Selector, load_model
    from pipeline.tuning.smbo import TrialsSection

    refuse_json_on_stdout(out, as_json)
    refuse_input_as_output(out, [sequence, params_path, *sorted(model_dir.glob("*"))])
    # the adapter's untuned settings as in the trials (without a params file, its defaults)
    options = load_section(params_path, "trials", TrialsSection).adapter_options
    selection = load_section(params_path, "select", SelectSection).settings()
    model = load_model(model_dir, expected_algorithm=algorithm,
                       declared_space=declared_space)
    selector = Selector(model, selection)
    report_selection({"algorithm": model.algorithm,
                      **run_live(model, sequence, out, selector, adapter_options=options),
                      "out": str(out)}, as_json)
