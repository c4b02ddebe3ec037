"""Read-only SQL against the results database, rendered as a text table, CSV, JSON or Parquet."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import pyarrow as pa

from pipeline.errors import InputError, QueryError
from pipeline.io_utils import atomic_path, atomic_write_text

QUERY_FORMATS = ("table", "csv", "json", "parquet")


def query_database(db_path: str | Path, sql: str, fmt: str = "table",
                   out: str | Path | None = None) -> str:
    """Run ``sql`` on a read-only connection; return the text to print ('' when written to ``out``).

    ``parquet`` needs ``out``; the other formats go to ``out`` when given, else are returned.
    """
    if fmt not in QUERY_FORMATS:
        raise InputError(f"unknown format '{fmt}', known: {list(QUERY_FORMATS)}")
    if fmt == "parquet" and out is None:
        raise InputError("--format parquet needs --out FILE")
    table = run_query(db_path, sql)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        with atomic_path(out) as tmp:  # type: ignore[arg-type]
            pq.write_table(table, tmp, compression="zstd")
        return ""
    text = {"table": format_table, "csv": format_csv, "json": format_json}[fmt](table)
    if out is not None:
        atomic_write_text(out, text)
        return ""
    return text


def run_query(db_path: str | Path, sql: str) -> pa.Table:
    """Result of ``sql`` as an Arrow table (empty when the statement returns nothing)."""
    import duckdb

    db_path = Path(db_path)
    if not db_path.is_file():
        raise InputError(f"{db_path}: no such database (build it with `adaptune rte`)")
    try:
        con = duckdb.connect(str(db_path), read_only=True)
    except duckdb.Error as exc:
        raise InputError(f"{db_path}: not a readable DuckDB database "
                         f"({_first_line(exc)})") from None
    try:
        rel = con.sql(sql)
        return rel.to_arrow_table() if rel is not None else pa.table({})
    except duckdb.Error as exc:
        raise QueryError(f"{db_path}: {_first_line(exc)}") from None
    finally:
        con.close()


def format_table(table: pa.Table) -> str:
    """Fixed-width text table: header, rule, one line per row (all rows)."""
    names = table.column_names
    if not names:
        return ""
    cols = [[_cell(v) for v in table.column(n).to_pylist()] for n in names]
    widths = [max([len(n), *map(len, c)]) for n, c in zip(names, cols, strict=True)]
    numeric = [pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_decimal(t)
               for t in table.schema.types]

    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) if num else c.ljust(w)
                         for c, w, num in zip(cells, widths, numeric, strict=True)).rstrip()

    rows = [line(list(r)) for r in zip(*cols, strict=True)] if cols else []
    footer = f"({table.num_rows} row{'s' if table.num_rows != 1 else ''})"
    return "\n".join([line(names), line(["-" * w for w in widths]), *rows, footer])


def format_csv(table: pa.Table) -> str:
    """CSV with a header line."""
    import pyarrow.csv as pcsv

    buf = io.BytesIO()
    pcsv.write_csv(table, buf)
    return buf.getvalue().decode("utf-8")


def format_json(table: pa.Table) -> str:
    """A JSON array of row objects (NaN and infinities become null)."""
    rows = [{k: _json_value(v) for k, v in r.items()} for r in table.to_pylist()]
    return json.dumps(rows, indent=1, default=str) + "\n"


def _cell(v: Any) -> str:
    if v is None:
        return "NULL"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
