"""`adaptune query "SQL"`: read-only SQL against the results database."""

from __future__ import annotations

from pathlib import Path

import click

FORMATS = ["table", "csv", "json", "parquet"]


@click.command()
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
