"""`adaptune query "SQL"`: read-only, sandboxed SQL against the results database."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from stages.common import file_option, read_text_argument, refuse_dash, write_output

FORMATS = ["table", "csv", "json", "parquet"]
QUERY_TIME_LIMIT_S = 60.0
"""pipeline.database.query.QUERY_TIME_LIMIT_S (kept here so that --help imports nothing)."""


EXAMPLES = """\b
Examples:
  adaptune query "SELECT algorithm, sequence, arg_min(trial, mean_rte_pct) AS best_trial,
    min(mean_rte_pct) AS rte_pct FROM trials WHERE status = 'ok' GROUP BY ALL ORDER BY ALL"
  adaptune query "SELECT algorithm, label, avg(t_err_pct) AS rte_pct, count(*) AS frames
    FROM rte_labelled GROUP BY ALL ORDER BY ALL"
  adaptune query "SELECT round(p_keyframe_interval) AS kf, avg(mean_rte_pct) AS rte_pct
    FROM trials WHERE algorithm = 'gicp' AND status = 'ok' GROUP BY 1 ORDER BY 1"
  adaptune query "SELECT * FROM surrogate_rows" --format parquet --out rows.parquet
  adaptune query - < report.sql
  adaptune query "SELECT r.* FROM rows r JOIN sequences USING (sequence)" --table rows=rows.parquet

\b
The SQL cannot read or write files (COPY, EXPORT DATABASE, read_csv, ATTACH, INSTALL fail):
--table exposes a local Parquet file as a read-only view, --out writes the result. A query
stops after --time-limit-s (60 s by default).
"""


def _tables(pairs: tuple[str, ...]) -> dict[str, Path]:
    from pipeline.errors import ConfigError

    tables: dict[str, Path] = {}
    for pair in pairs:
        name, sep, path = pair.partition("=")
        if not sep or not name or not path:
            raise ConfigError(f"--table must be NAME=FILE.parquet, got {pair!r}")
        if path == "-":
            refuse_dash(f"--table {pair}")
        tables[name] = Path(path)
    return tables


@click.command(epilog=EXAMPLES)
@click.argument("sql")
@file_option("--db", default=Path("results/adaptune.duckdb"), show_default=True,
             help="The database.")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="table", show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              default=None,
              help="Write the result to this file (- or none: stdout).")
@click.option("--table", "table_pairs", multiple=True, metavar="NAME=FILE",
              help="Let the SQL read a local Parquet file (or folder) as the view NAME "
              "(repeatable).")
@click.option("--time-limit-s", type=float, default=QUERY_TIME_LIMIT_S, show_default=True,
              help="Stop the query after this many seconds.")
def query(sql: str, db: Path, fmt: str, out: Path | None, table_pairs: tuple[str, ...],
          time_limit_s: float) -> None:
    """Run SQL (or - to read it from stdin) on the results database, opened read-only and
    sandboxed, and print or write the result."""
    from pipeline.database.query import query_database

    to_stdout = out is None or str(out) == "-"
    if to_stdout and fmt == "parquet" and sys.stdout.isatty():
        from pipeline.errors import ConfigError

        raise ConfigError("--format parquet is binary: give --out FILE (or pipe stdout)")
    data = query_database(db, read_text_argument(sql, "SQL"), fmt,
                          None if to_stdout else out, _tables(table_pairs), time_limit_s)
    if to_stdout:
        write_output(data)
