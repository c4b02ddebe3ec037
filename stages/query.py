"""`adaptune query "SQL"`: read-only SQL against the results database."""

from __future__ import annotations

from pathlib import Path

import click

FORMATS = ["table", "csv", "json", "parquet"]


EXAMPLES = """\b
Examples:
  adaptune query "SELECT algorithm, sequence, arg_min(trial, mean_rte_pct) AS best_trial,
    min(mean_rte_pct) AS rte_pct FROM trials WHERE status = 'ok' GROUP BY ALL ORDER BY ALL"
  adaptune query "SELECT algorithm, label, avg(t_err_pct) AS rte_pct, count(*) AS frames
    FROM rte_labelled GROUP BY ALL ORDER BY ALL"
  adaptune query "SELECT round(p_keyframe_interval) AS kf, avg(mean_rte_pct) AS rte_pct
    FROM trials WHERE algorithm = 'gicp' AND status = 'ok' GROUP BY 1 ORDER BY 1"
  adaptune query "SELECT * FROM surrogate_rows" --format parquet --out rows.parquet
"""


@click.command(epilog=EXAMPLES)
@click.argument("sql")
@click.option("--db", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("results/adaptune.duckdb"), show_default=True, help="The database.")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="table", show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the result to this file instead of stdout (needed for parquet).")
def query(sql: str, db: Path, fmt: str, out: Path | None) -> None:
    """Run SQL on the results database (opened read-only) and print or write the result."""
    from pipeline.evaluation.query import query_database

    text = query_database(db, sql, fmt, out)
    if text:
        click.echo(text, nl=not text.endswith("\n"))
