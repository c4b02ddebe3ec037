"""Text tables: adaptune's renderer (pipeline/text_table.py) against DuckDB's and rich's, same
run, on 10,000 rows of five columns (a trials table: text, integers, floats).

The figures that keep our renderer (issue 18.6): DuckDB's relation renderer reads at most
10,000 rows whatever ``max_rows`` says (a 12,000-row result shows 10,000 and "? rows"), and
rich's Table is two orders of magnitude slower.
"""

from __future__ import annotations

import io

import numpy as np
from common import Row, best_of, size

ROWS = size(10_000, 200)


def _table(n: int):  # type: ignore[no-untyped-def]
    import pyarrow as pa

    rng = np.random.default_rng(0)
    return pa.table({"sequence": [f"seq_{i % 7:02d}" for i in range(n)],
                     "trial": np.arange(n, dtype=np.int32), "rte_pct": rng.random(n) * 5,
                     "resolution": rng.random(n) * 9 + 1, "status": ["ok"] * n})


def _rich(table) -> str:  # type: ignore[no-untyped-def]
    import pyarrow as pa
    from rich import box
    from rich.console import Console
    from rich.table import Table

    out = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
    for name, kind in zip(table.column_names, table.schema.types, strict=True):
        numeric = pa.types.is_integer(kind) or pa.types.is_floating(kind)
        out.add_column(name, justify="right" if numeric else "left", no_wrap=True)
    cols = [[f"{v:.6g}" if isinstance(v, float) else str(v) for v in table.column(c).to_pylist()]
            for c in table.column_names]
    for row in zip(*cols, strict=True):
        out.add_row(*row)
    buf = io.StringIO()
    Console(file=buf, width=10_000, color_system=None).print(out)
    return buf.getvalue()


def _duckdb_show(con, table, max_rows: int) -> str:  # type: ignore[no-untyped-def]
    import contextlib

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        con.from_arrow(table).show(max_rows=max_rows, max_width=10_000)
    return buf.getvalue()


def run() -> list[Row]:
    import duckdb

    from pipeline.text_table import format_table

    table = _table(ROWS)
    con = duckdb.connect()
    ours = best_of(lambda: format_table(table), 5)
    theirs = best_of(lambda: _duckdb_show(con, table, ROWS), 5)
    slow = best_of(lambda: _rich(table), 1)
    big = _table(12_000)
    shown = sum(1 for line in _duckdb_show(con, big, 10**9).splitlines()
                if line.startswith("│ seq_"))
    return [
        Row(f"render {ROWS} rows x 5 columns as text (ours)", 1e3 * ours, "ms",
            f"duckdb show(): {1e3 * theirs:.0f} ms; rich Table: {1e3 * slow:.0f} ms "
            f"({slow / ours:.0f}x)", "a library unless a measured reason"),
        Row("duckdb show(max_rows=1e9): rows shown of a 12000-row result", float(shown), "rows",
            "ours: 12000 (every row)", "every row"),
    ]
