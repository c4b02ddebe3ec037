"""The one text table renderer of the command line (``query``, ``params``, ``info``).

Why not a library's (measured with ``make bench``, bench/bench_table.py):
DuckDB's relation renderer (``show()`` / ``str()``) reads at most 10,000 rows of a relation,
whatever its ``max_rows``, and ends larger results with "? rows", while ``adaptune query``
promises every row; rich's ``Table`` shows every row but took 13.9 s for 10,000 rows of five
columns, against 0.08 s here.
"""

from __future__ import annotations

from typing import Any

import pyarrow as pa


def format_table(table: pa.Table, footer: bool = True) -> str:
    """Fixed-width text of every row of ``table``: the column names, a rule, one line a row
    (numbers right-aligned, floats to 6 significant digits, NULL for missing values) and,
    with ``footer``, the row count."""
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

    rows = [line(list(r)) for r in zip(*cols, strict=True)]
    count = [f"({table.num_rows} row{'s' if table.num_rows != 1 else ''})"] if footer else []
    return "\n".join([line(names), line(["-" * w for w in widths]), *rows, *count])


def _cell(v: Any) -> str:
    if v is None:
        return "NULL"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)
