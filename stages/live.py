"""`adaptune live MODEL SEQ.mcap --out OUT.mcap`: scans streamed one by one through the odometry,
parameters chosen online every period and pushed into it; the output MCAP holds the scans, the
ground truth, the anchored estimate (``/odometry/pose``, ``/tf``) and the parameters
(``/adaptune/params``, rcl_interfaces/msg/ParameterEvent), all ROS 2 types, for Foxglove
(``pipeline.live`` documents the channels and frames)."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import (
    algorithm_option,
    file_option,
    json_option,
    model_argument,
    report,
    sequence_argument,
)


@click.command()
@model_argument
@sequence_argument
@file_option("--out", help="Output MCAP (scans, ground truth, estimated poses, chosen parameters).")
@algorithm_option("Odometry algorithm (default: the model's; another one is refused).")
@json_option
def live(model_dir: Path, sequence: Path, out: Path, algorithm: str | None,
         as_json: bool) -> None:
    """Stream a sequence through odometry with online parameter selection."""
    from pipeline.live import run_live
    from pipeline.runtime import load_model

    model = load_model(model_dir, expected_algorithm=algorithm)
    summary = {"algorithm": model.algorithm, **run_live(model, sequence, out), "out": str(out)}
    report(summary, f"{model.algorithm}: {summary['frames']} frames, {summary['selections']} "
           f"selections, {summary['changes']} parameter changes -> {out}", as_json)
