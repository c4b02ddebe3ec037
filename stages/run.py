"""``adaptune run``: one odometry run over a sequence MCAP, fixed parameters or a schedule."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from stages.common import (
    FILE,
    algorithm_option,
    file_option,
    json_option,
    refuse_dash,
    report,
    sequence_argument,
)


def parse_params(text: str | None) -> dict[str, float]:
    """``--params``: a JSON object, or ``@file`` holding one. ConfigError otherwise."""
    from pipeline.errors import ConfigError

    if text is None:
        return {}
    source = "--params"
    if text.startswith("@"):
        from pipeline.io_utils import read_input_text

        if text == "@-":
            refuse_dash("--params @-")
        path = Path(text[1:])
        text = read_input_text(path, "parameters file", error=ConfigError, strict=True)
        source = str(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{source}: not valid JSON ({exc.msg})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: must be a JSON object of parameter name -> value")
    return data


def parse_options(pairs: tuple[str, ...]) -> dict[str, Any]:
    """``--option key=value`` pairs; a value that parses as JSON is taken as JSON."""
    from pipeline.errors import ConfigError

    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ConfigError(f"--option must be key=value, got {pair!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


@click.command("run")
@algorithm_option("Adapter name (ndt, gicp, kiss_icp, command).", required=True)
@click.option("--params", "params_json", default=None,
              help="Fixed parameters as a JSON object or @file.json (missing ones: baseline).")
@click.option("--schedule", "schedule_path", type=FILE, default=None,
              help="Per-frame parameter schedule (Parquet).")
@file_option("--out", "out_path", help="Trajectory Parquet to write.")
@click.option("--option", "-o", "options", multiple=True,
              help="Adapter option key=value (repeatable), e.g. -o source_voxel_m=0.5.")
@click.option("--time-limit", "time_limit_s", type=float, default=None, help="Seconds.")
@json_option
@sequence_argument
def run(algorithm: str, params_json: str | None, schedule_path: Path | None, out_path: Path,
        options: tuple[str, ...], time_limit_s: float | None, as_json: bool,
        sequence: Path) -> None:
    """Run ALGORITHM once over SEQUENCE (a sequence MCAP) and write its trajectory."""
    from pipeline.errors import ConfigError
    from pipeline.io_utils import refuse_input_as_output
    from pipeline.odometry import get_adapter, run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.trajectory import write_trajectory

    if params_json is not None and schedule_path is not None:
        raise ConfigError("give --params or --schedule, not both")
    params_file = params_json[1:] if params_json and params_json.startswith("@") else None
    refuse_input_as_output(out_path, [sequence, schedule_path, params_file])
    adapter = get_adapter(algorithm, **parse_options(options))
    given = Schedule.read(schedule_path) if schedule_path else parse_params(params_json)
    traj = run_sequence(adapter, sequence, given, time_limit_s=time_limit_s)
    meta = {"algorithm": algorithm, "sequence": str(sequence)}
    if schedule_path:
        meta["schedule"] = str(schedule_path)
    else:
        meta["params_json"] = json.dumps(adapter.space.validate(given))  # type: ignore[arg-type]
    write_trajectory(out_path, traj, meta)
    summary = {"algorithm": algorithm, "sequence": str(sequence), "poses": len(traj),
               "out": str(out_path)}
    report(summary, f"{algorithm}: {len(traj)} poses -> {out_path}", as_json)
