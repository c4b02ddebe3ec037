"""`adaptune live MODEL SEQ.mcap --out OUT.mcap`: scans streamed one by one through the odometry,
parameters chosen online every period and pushed into it; the output MCAP holds the scans, the
ground truth, ``/odometry/pose`` (PoseStamped) and ``/adaptune/params`` (JSON) for Foxglove."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import algorithm_option, file_option, model_argument, sequence_argument


@click.command()
@model_argument
@sequence_argument
@file_option("--out", help="Output MCAP (scans, ground truth, estimated poses, chosen parameters).")
@algorithm_option("Odometry algorithm (default: the model's; another one is refused).")
def live(model_dir: Path, sequence: Path, out: Path, algorithm: str | None) -> None:
    """Stream a sequence through odometry with online parameter selection."""
    from pipeline.runtime import load_model, run_live

    model = load_model(model_dir, expected_algorithm=algorithm)
    summary = run_live(model, sequence, out)
    click.echo(
        f"{model.algorithm}: {summary['frames']} frames, {summary['selections']} selections, "
        f"{summary['changes']} parameter changes -> {out}",
        err=True,
    )
