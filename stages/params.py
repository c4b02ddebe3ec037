"""``adaptune params ALGO``: the parameters an adapter tunes, with their ranges and defaults.

Without ``--params`` the adapter's built-in ranges; with it, the ranges a trials run with that
params file searches (its ``trials.space`` applied, when its ``trials.algorithm`` is ALGO).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from stages.common import FILE, echo_output, json_option


@click.command("params")
@click.argument("algorithm")
@click.option("--option", "-o", "options", multiple=True,
              help="Adapter option key=value (repeatable; the command adapter's space).")
@click.option("--params", "params_path", type=FILE, default=None,
              help="A params file: show the ranges its trials section searches.")
@json_option
def params(algorithm: str, options: tuple[str, ...], params_path: Path | None,
           as_json: bool) -> None:
    """List the parameters ALGORITHM tunes: range, default, kind, scale, unit."""
    from stages.run import configured_adapter, parse_options

    if params_path is not None:
        adapter, source = configured_adapter(params_path, algorithm, parse_options(options))
    else:
        from pipeline.odometry.registry import build_adapter

        adapter, source = build_adapter(algorithm, parse_options(options)), "built-in"
    specs = adapter.space.to_json()
    if as_json:
        echo_output(json.dumps({"algorithm": adapter.name, "source": source,
                               "parameters": specs}, indent=2))
        return
    import pyarrow as pa

    from pipeline.text_table import format_table

    table = pa.table({
        "name": [str(s["name"]) for s in specs], "low": [f"{s['low']:g}" for s in specs],
        "high": [f"{s['high']:g}" for s in specs],
        "default": [f"{s['default']:g}" for s in specs], "kind": [str(s["kind"]) for s in specs],
        "scale": ["log" if s["log"] else "linear" for s in specs],
        "unit": [str(s["unit"]) for s in specs]})
    echo_output(f"{adapter.name}: {len(specs)} parameters ({source} ranges)\n"
                + format_table(table, footer=False))
