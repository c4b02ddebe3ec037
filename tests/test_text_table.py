"""The one text table renderer (pipeline.text_table) of query, params and info."""

from __future__ import annotations

import pyarrow as pa

from pipeline.text_table import format_table


def test_columns_align_by_type_and_missing_values_read_null() -> None:
    table = pa.table({"sequence": ["seq_a", None], "trial": [3, 12],
                      "rte_pct": [1.23456789, None]})
    assert format_table(table).splitlines() == [
        "sequence  trial  rte_pct",
        "--------  -----  -------",
        "seq_a         3  1.23457",
        "NULL         12     NULL",
        "(2 rows)",
    ]
    assert format_table(table, footer=False).splitlines()[-1] == "NULL         12     NULL"


def test_every_row_shows_beyond_duckdbs_ten_thousand() -> None:
    n = 12_000  # DuckDB's own renderer stops at 10,000 rows ("? rows")
    lines = format_table(pa.table({"k": list(range(n))})).splitlines()
    assert len(lines) == n + 3 and lines[-2].strip() == str(n - 1) and lines[-1] == "(12000 rows)"


def test_an_empty_result() -> None:
    assert format_table(pa.table({})) == ""
    assert format_table(pa.table({"x": pa.array([], pa.int64())})).splitlines() == [
        "x", "-", "(0 rows)"]
