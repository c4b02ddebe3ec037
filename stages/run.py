"""``adaptune run``: one odometry run over a sequence MCAP, fixed parameters or a schedule.

The adapter is built as the trials stage builds it from the params file (``--params``, default
./params.yaml): its trials.algorithm unless ``--algorithm`` names another, its
trials.adapter_options with ``-o`` over them, its trials.space. The trajectory's metadata names
the sequence (and schedule) by absolute path, so ``adaptune export`` finds them from anywhere.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import click

from stages.common import (
    FILE,
    algorithm_option,
    json_option,
    out_option,
    refuse_dash,
    refuse_json_on_stdout,
    report,
    sequence_argument,
)


def parse_params(text: str | None, flag: str = "--values") -> dict[str, float]:
    """``--values``: a JSON object, or ``@file`` holding one. ConfigError otherwise."""
    from pipeline.errors import ConfigError

    if text is None:
        return {}
    source = flag
    if text.startswith("@"):
        from pipeline.io_utils import read_input_text

        if text == "@-":
            refuse_dash("--params @-")
        path = Path(text[1:])
        text = read_input_text(path, "parameters file", error=ConfigError, strict=True)
        source = str(path)
    from pipeline.json_yaml import parse_json

    data = parse_json(text, source, error=ConfigError)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: must be a JSON object of parameter name -> value")
    return data


def is_values(text: str) -> bool:
    """True for ``--params`` in its old form, parameter values (a JSON object or ``@file``),
    not a params file."""
    return text.lstrip()[:1] in ("{", "[", "@")


def _params_arg(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """--params as given (a params file, or values in the old form); else ./params.yaml where
    there is one."""
    if value is not None:
        return value
    return "params.yaml" if Path("params.yaml").exists() else None


def configured_adapter(params_path: Path | None, algorithm: str | None,
                       options: dict[str, Any]) -> tuple[Any, str]:
    """(adapter, where its ranges come from) as a trials run with the params file at
    ``params_path`` builds it: ``algorithm`` [trials.algorithm], trials.adapter_options and
    ``options`` over them, and trials.space when the algorithm is trials.algorithm."""
    from pipeline.config import load_section, validate_section
    from pipeline.odometry.registry import build_adapter
    from pipeline.tuning.section import TrialsSection
    from pipeline.tuning.smbo import study_adapter

    trials = load_section(params_path, "trials", TrialsSection)
    name = algorithm or trials.algorithm
    if name != trials.algorithm:
        return build_adapter(name, options), "built-in"
    settings = validate_section(TrialsSection, "trials", {
        **trials.model_dump(), "adapter_options": {**trials.adapter_options, **options}})
    source = f"{params_path} trials.space" if trials.space else "built-in"
    return study_adapter(settings), source


def parse_options(pairs: tuple[str, ...]) -> dict[str, Any]:
    """``--option key=value`` pairs; a value that parses as JSON is taken as JSON."""
    from pipeline.errors import ConfigError
    from pipeline.json_yaml import check_json_nesting

    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ConfigError(f"--option must be key=value, got {pair!r}")
        check_json_nesting(value, f"--option {key}", error=ConfigError)
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def relative_to_output(path: Path, out_path: Path) -> str:
    """``path`` relative to the output's folder, as the pipeline's trajectories name their
    inputs: the file's bytes do not depend on where the project lies."""
    return os.path.relpath(Path(path).resolve(), Path(out_path).resolve().parent)


@click.command("run")
@algorithm_option("Adapter name (ndt, gicp, kiss_icp, command) [trials.algorithm].")
@click.option("--params", "params_arg", default=None, callback=_params_arg,
              help="The params file: trials.algorithm, trials.adapter_options and "
              "trials.space, as the trials stage runs it [default: ./params.yaml if there is "
              "one]. (A JSON object or @file.json here is --values, the older form.)")
@click.option("--values", "values_json", default=None,
              help="Fixed parameter values as a JSON object or @file.json (missing ones: the "
              "baseline).")
@click.option("--schedule", "schedule_path", type=FILE, default=None,
              help="Per-frame parameter schedule (Parquet).")
@out_option("out_path", help="Trajectory Parquet to write")
@click.option("--option", "-o", "options", multiple=True,
              help="Adapter option key=value (repeatable), e.g. -o source_voxel_m=0.5.")
@click.option("--time-limit", "time_limit_s", type=float, default=None, help="Seconds.")
@json_option
@sequence_argument
def run(algorithm: str | None, params_arg: str | None, values_json: str | None,
        schedule_path: Path | None, out_path: Path, options: tuple[str, ...],
        time_limit_s: float | None, as_json: bool, sequence: Path) -> None:
    """Run an odometry once over SEQUENCE (a sequence MCAP) and write its trajectory."""
    from pipeline.errors import ConfigError
    from pipeline.io_utils import refuse_input_as_output
    from pipeline.odometry import run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.trajectory import write_trajectory

    refuse_json_on_stdout(out_path, as_json)
    params_path = None
    values_flag = "--values"
    if params_arg is not None and is_values(params_arg):
        if values_json is not None:
            raise ConfigError("give the parameter values once: --values (--params JSON is its "
                              "older form)")
        values_json, values_flag = params_arg, "--params"
    elif params_arg is not None:
        params_path = Path(params_arg)
    if values_json is not None and schedule_path is not None:
        raise ConfigError(f"give {values_flag} or --schedule, not both")
    values_file = values_json[1:] if values_json and values_json.startswith("@") else None
    refuse_input_as_output(out_path, [sequence, schedule_path, values_file, params_path])
    adapter, _ = configured_adapter(params_path, algorithm, parse_options(options))
    given = (Schedule.read(schedule_path) if schedule_path
             else parse_params(values_json, values_flag))
    traj = run_sequence(adapter, sequence, given, time_limit_s=time_limit_s, show_progress=True)
    meta = {"algorithm": adapter.name, "sequence": relative_to_output(sequence, out_path)}
    if schedule_path:
        meta["schedule"] = relative_to_output(schedule_path, out_path)
    else:
        meta["params_json"] = json.dumps(adapter.space.validate(given))  # type: ignore[arg-type]
    write_trajectory(out_path, traj, meta)
    summary = {"algorithm": adapter.name, "sequence": str(sequence), "poses": len(traj),
               "out": str(out_path)}
    report(summary, f"{adapter.name}: {len(traj)} poses -> {out_path}", as_json)
