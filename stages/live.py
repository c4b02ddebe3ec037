"""`adaptune live MODEL SEQ.mcap --out OUT.mcap`: scans streamed one by one through the odometry,
parameters chosen online every period and pushed into it; the output MCAP holds the ground
truth, the anchored estimate (``/odometry/pose``, ``/tf``), the parameters (``/adaptune/params``,
rcl_interfaces/msg/ParameterEvent) and, with ``--scans``, the scans, all ROS 2 types, for
Foxglove (``pipeline.live`` documents the channels and frames). ``--serve`` shows the run in
Foxglove while it runs (``pipeline.live_view``)."""

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
@model_run_options("Output MCAP (ground truth, estimated poses, chosen parameters; the scans "
                   "with --scans).")
@click.option("--scans/--no-scans", default=False, show_default=True,
              help="Keep the scans in the output MCAP (1.4 MB a KITTI frame).")
@click.option("--serve", is_flag=True,
              help="Show the run in Foxglove while it runs: a WebSocket server on "
              "--host:--port; the run starts when a client connects, and the server stays "
              "until the clients leave.")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="With --serve: the address to listen on (0.0.0.0: every interface).")
@click.option("--port", type=click.IntRange(0, 65535), default=8765, show_default=True,
              help="With --serve: the port (0: a free one, printed).")
def live(params_path: Path | None, model_dir: Path, sequence: Path, out: Path,
         algorithm: str | None, as_json: bool, scans: bool, serve: bool, host: str,
         port: int) -> None:
    """Stream a sequence through odometry with online parameter selection (the selector's
    settings: params ``select``)."""
    from pipeline.config import SelectSection, load_section
    from pipeline.io_utils import refuse_input_as_output
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
    if serve:
        from pipeline.live_view import serve_live

        summary = serve_live(model, sequence, out, selector, options, scans=scans, host=host,
                             port=port)
    else:
        from pipeline.live import run_live

        summary = run_live(model, sequence, out, selector, adapter_options=options,
                           scans=scans)
    report_selection({"algorithm": model.algorithm, **summary, "out": str(out)}, as_json)
