"""`adaptune query`: the SQL runs sandboxed (no file access, locked configuration), a local
Parquet file only through --table, the result only through --out or stdout."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from helpers.evaluation_data import cli_fails

from stages.cli import main

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def db(tmp_path: Path) -> Path:
    """A small results database (tables trials and sequences) beside a secret file."""
    path = tmp_path / "adaptune.duckdb"
    con = duckdb.connect(str(path))
    con.execute("CREATE TABLE trials AS SELECT range AS trial, range * 0.5::DOUBLE AS mean_rte_pct "
                "FROM range(4)")
    con.execute("CREATE TABLE sequences AS SELECT 'cave_0' AS sequence")
    con.close()
    (tmp_path / "secret.csv").write_text("a,b\n1,2\n")
    return path


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


ESCAPES = [
    ("COPY (SELECT 1) TO '{tmp}/out.csv'", "out.csv"),
    ("COPY trials TO '{db}'", "adaptune.duckdb"),
    ("COPY (SELECT 1) TO '{tmp}/x.parquet' (FORMAT parquet, USE_TMP_FILE false)", "x.parquet"),
    ("EXPORT DATABASE '{tmp}/export'", "export"),
    ("SELECT * FROM read_csv('/etc/passwd')", "/etc/passwd"),
    ("SELECT * FROM read_csv('{tmp}/secret.csv')", "secret.csv"),
    ("SELECT * FROM '{tmp}/secret.csv'", "secret.csv"),
    ("SELECT * FROM read_text('{tmp}/secret.csv')", "secret.csv"),
    ("SELECT * FROM sniff_csv('{tmp}/secret.csv')", "secret.csv"),
    ("SELECT * FROM glob('/etc/*')", "/etc/*"),
    ("ATTACH '{tmp}/other.duckdb' AS other", "other.duckdb"),
    ("INSTALL httpfs", "extensions"),
    ("LOAD httpfs", "disabled"),
    ("SET enable_external_access = true", "locked"),
    ("RESET enable_external_access", "locked"),
    ("SET lock_configuration = false", "locked"),
    ("CREATE TABLE evil AS SELECT 1", "read-only"),
]


@pytest.mark.parametrize("sql, needle", ESCAPES, ids=[s.split()[0] + str(i)
                                                      for i, (s, _) in enumerate(ESCAPES)])
def test_sql_cannot_touch_files_or_unlock(db: Path, sql: str, needle: str) -> None:
    tmp = db.parent
    before = _files(tmp)
    cli_fails(["query", "--db", str(db), sql.format(tmp=tmp, db=db)], needle)
    assert _files(tmp) == before


def test_file_errors_say_how_to_read_a_file(db: Path) -> None:
    line = cli_fails(["query", "--db", str(db), "SELECT * FROM read_csv('/etc/passwd')"])
    assert "--table NAME=FILE.parquet" in line and "--out FILE" in line


def test_table_option_reads_a_parquet_file_read_only(db: Path, tmp_path: Path) -> None:
    rows = tmp_path / "rows.parquet"
    pq.write_table(pa.table({"trial": [1, 3], "note": ["a", "b"]}), rows)
    before = rows.read_bytes()
    sql = ("SELECT r.trial, r.note, t.mean_rte_pct FROM rows r JOIN trials t USING (trial) "
           "ORDER BY 1")
    result = CliRunner().invoke(main, ["query", "--db", str(db), sql, "--format", "json",
                                       "--table", f"rows={rows}"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == [{"trial": 1, "note": "a", "mean_rte_pct": 0.5},
                                         {"trial": 3, "note": "b", "mean_rte_pct": 1.5}]
    # the view is readable, the file behind it is not writable from SQL
    cli_fails(["query", "--db", str(db), "--table", f"rows={rows}",
               f"COPY (SELECT 1 AS x) TO '{rows}' (FORMAT parquet, USE_TMP_FILE false)"],
              "rows.parquet")
    assert rows.read_bytes() == before


def test_table_option_errors(db: Path, tmp_path: Path) -> None:
    rows = tmp_path / "rows.parquet"
    pq.write_table(pa.table({"x": [1]}), rows)
    cli_fails(["query", "--db", str(db), "SELECT 1", "--table", f"trials={rows}"],
              "--table trials=", "not one of the database's tables")
    cli_fails(["query", "--db", str(db), "SELECT 1", "--table", f"a-b={rows}"], "identifier")
    cli_fails(["query", "--db", str(db), "SELECT 1", "--table", "rows"], "NAME=FILE.parquet")
    cli_fails(["query", "--db", str(db), "SELECT 1", "--table", f"r={tmp_path / 'no.parquet'}"],
              "no.parquet", "no such Parquet file")
    cli_fails(["query", "--db", str(db), "SELECT 1", "--table", f"r={tmp_path / 'secret.csv'}"],
              "secret.csv", "not a readable Parquet file")


def test_out_writes_the_result_and_never_replaces_an_input(db: Path, tmp_path: Path) -> None:
    out = tmp_path / "best.csv"
    result = CliRunner().invoke(main, ["query", "--db", str(db), "SELECT max(trial) AS m "
                                       "FROM trials", "--format", "csv", "--out", str(out)])
    assert result.exit_code == 0 and result.stdout == ""
    assert out.read_text() == "\"m\"\n3\n"
    before = db.read_bytes()
    cli_fails(["query", "--db", str(db), "SELECT 1", "--out", str(db)],
              "is an input of the query")
    assert db.read_bytes() == before


def test_dash_reads_sql_from_stdin_and_writes_stdout(db: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(main, ["query", "--db", str(db), "-", "--format", "csv", "--out", "-"],
                           input="SELECT count(*) AS n\nFROM trials\n")
    assert result.exit_code == 0, result.output
    assert result.stdout == "\"n\"\n4\n"
    result = runner.invoke(main, ["query", "--db", str(db), "SELECT trial FROM trials",
                                  "--format", "parquet", "--out", "-"])
    assert result.exit_code == 0
    assert pq.read_table(io.BytesIO(result.stdout_bytes)).column("trial").to_pylist() == [
        0, 1, 2, 3]
    cli_fails(["query", "--db", str(db), "-"], "stdin", "got nothing")


LONG_SQL = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"
"""A cross join that runs for hours."""


def test_sql_cannot_reach_duckdbs_temporary_folder(db: Path) -> None:
    """Issue 32, case 2: DuckDB allowed `<db>.tmp/` (its temp_directory) with external access
    off; when the folder existed the SQL could COPY into it (6.9 MB were written), read_csv
    from it and glob it. Spilling is off now, and the folder is like any other."""
    tmp = db.parent / f"{db.name}.tmp"
    tmp.mkdir()
    (tmp / "old.csv").write_text("a\n1\n")
    before = _files(db.parent)
    for sql in (f"COPY (SELECT 1) TO '{tmp}/x.csv'", f"SELECT * FROM read_csv('{tmp}/old.csv')",
                f"SELECT * FROM glob('{tmp}/*')", f"SET temp_directory = '{tmp}'"):
        cli_fails(["query", "--db", str(db), sql])
    assert _files(db.parent) == before


def test_a_query_stops_at_its_time_limit(db: Path) -> None:
    """Issue 32, case 4: no query had a time limit (a cross join ran forever)."""
    from pipeline.database.query import QUERY_TIME_LIMIT_S
    from stages.query import QUERY_TIME_LIMIT_S as CLI_DEFAULT

    assert CLI_DEFAULT == QUERY_TIME_LIMIT_S == 60.0
    cli_fails(["query", "--db", str(db), "--time-limit-s", "0.5", LONG_SQL],
              "time limit of 0.5 s", "--time-limit-s")
    cli_fails(["query", "--db", str(db), "--time-limit-s", "0", "SELECT 1"],
              "--time-limit-s must be", "> 0")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_query_is_one_line_and_exit_130(db: Path, sig: int) -> None:
    """Issue 32, case 7: Ctrl-C or SIGTERM during a query was a traceback ('RuntimeError:
    Query interrupted'); now one line and exit code 130."""
    proc = subprocess.Popen([sys.executable, "-m", "stages.cli", "query", "--db", str(db),
                             LONG_SQL], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(REPO)},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 60
        while not _has_open(proc.pid, db):  # the database is open: the query is next (a
            # signal before DuckDB executes must stop it too)
            assert proc.poll() is None and time.monotonic() < deadline, "no query started"
            time.sleep(0.05)
        proc.send_signal(sig)
        code = proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    lines = proc.stderr.read().decode().strip().splitlines()  # type: ignore[union-attr]
    assert code == 130 and lines == [f"adaptune: interrupted ({signal.Signals(sig).name})"], \
        (code, lines)


def _has_open(pid: int, path: Path) -> bool:
    try:
        return any(os.readlink(fd) == str(path) for fd in Path(f"/proc/{pid}/fd").iterdir())
    except (FileNotFoundError, ProcessLookupError):
        return False
