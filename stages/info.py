"""``adaptune info SEQ.mcap [--json]``: summary of a sequence MCAP."""

from __future__ import annotations

import json
from pathlib import Path

import click

from stages.common import FILE, echo_output


@click.command("info")
@click.argument("path", type=FILE)
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def info(path: Path, as_json: bool) -> None:
    """Frames, duration, ground-truth path length, points per scan, sensor, labels, schema."""
    from pipeline.info import summarize_sequence

    s = summarize_sequence(path)
    if as_json:
        echo_output(json.dumps(s.to_dict(), indent=2))
        return
    pps = s.points_per_scan
    rows = [
        ("name", s.name),
        ("frames", s.frames),
        ("duration", f"{s.duration_s:.3f} s"),
        (
            "ground truth",
            f"yes, path length {s.path_length_m:.2f} m" if s.has_ground_truth else "no",
        ),
        ("points per scan", f"min {pps['min']}, median {pps['median']:g}, max {pps['max']}"),
        ("sensor", s.sensor),
        ("source", s.source),
        ("labels", ", ".join(f"{a}-{b}: {lab}" for a, b, lab in s.labels) or "none"),
        ("schema version", s.schema_version),
        *((key.replace("_", " "), value) for key, value in sorted(s.details.items())),
    ]
    import pyarrow as pa

    from pipeline.text_table import format_table

    echo_output(format_table(pa.table({"field": [str(k) for k, _ in rows],
                                      "value": [str(v) for _, v in rows]}), footer=False))
