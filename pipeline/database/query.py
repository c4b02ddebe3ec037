"""Read-only, sandboxed SQL against the results database, rendered as a text table, CSV, JSON
or Parquet.

The SQL runs on a read-only connection whose external access is off and whose configuration is
locked (DuckDB's ``enable_external_access = false``, ``lock_configuration = true``): it cannot
read or write any file but the database (``COPY ... TO``, ``EXPORT DATABASE``, ``read_csv``,
``glob``, ``ATTACH``, ``INSTALL`` / ``LOAD`` all fail), nor turn that off again. Spilling to
disk is off (``temp_directory = ''``): DuckDB would otherwise allow the SQL into its temporary
folder (``<db>.tmp/``), the one folder external access leaves open. Local Parquet files the
user names (``tables``) are read by pyarrow and shown to the SQL as read-only views; writing
the result is the caller's ``out`` path, never the SQL's.

A statement is interrupted past its time limit (``QUERY_TIME_LIMIT_S`` by default: a
QueryError) and on SIGINT, SIGTERM or SIGHUP, which are handed on once it has stopped (DuckDB
turns a signal that arrives while it runs into its own error and loses which one it was).
"""

from __future__ import annotations

import io
import json
import math
import re
import signal
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa

from pipeline.errors import ConfigError, InputError, QueryError
from pipeline.io_utils import atomic_path, input_file
from pipeline.text_table import format_table

if TYPE_CHECKING:
    import duckdb

QUERY_FORMATS = ("table", "csv", "json", "parquet")
QUERY_TIME_LIMIT_S = 60.0
"""The default time limit of one query [s] (``adaptune query --time-limit-s``)."""
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_FILES_HINT = ("the SQL cannot open files: give --table NAME=FILE.parquet to query a local "
               "Parquet file as NAME, and --out FILE to write the result")


def query_database(db_path: str | Path, sql: str, fmt: str = "table",
                   out: str | Path | None = None,
                   tables: Mapping[str, str | Path] | None = None,
                   time_limit_s: float = QUERY_TIME_LIMIT_S) -> bytes:
    """Run ``sql`` in the sandbox; write the result to ``out`` (atomically) and return b"", or
    return it rendered (UTF-8 text, or Parquet bytes) when ``out`` is None.

    ``tables``: view name -> local Parquet file (or folder of them) the SQL may read.
    """
    if fmt not in QUERY_FORMATS:
        raise InputError(f"unknown format '{fmt}', known: {list(QUERY_FORMATS)}")
    if out is not None:
        _check_out(Path(out), Path(db_path), tables or {})
    data = render(run_query(db_path, sql, tables, time_limit_s), fmt)
    if out is None:
        return data
    with atomic_path(out) as tmp:
        tmp.write_bytes(data)
    return b""


def run_query(db_path: str | Path, sql: str,
              tables: Mapping[str, str | Path] | None = None,
              time_limit_s: float = QUERY_TIME_LIMIT_S) -> pa.Table:
    """Result of ``sql`` as an Arrow table (empty when the statement returns nothing).

    QueryError past ``time_limit_s``; SIGINT, SIGTERM and SIGHUP stop the statement and are
    then handed to their handlers (Ctrl-C: KeyboardInterrupt)."""
    import duckdb

    if not (isinstance(time_limit_s, int | float) and math.isfinite(time_limit_s)
            and time_limit_s > 0):
        raise ConfigError(f"--time-limit-s must be a finite number of seconds > 0, got "
                          f"{time_limit_s!r}")
    db_path = input_file(db_path, "database", " (build it with `adaptune rte`)")
    check_statements(sql)
    stopper = _Stopper(time_limit_s)
    con = None
    try:
        with stopper:  # from before the sandbox's own statements: a signal then stops them too
            con = stopper.con = open_sandbox(db_path, tables or {})
            rel = con.sql(sql)
            return rel.to_arrow_table() if rel is not None else pa.table({})
    except duckdb.InterruptException:
        if stopper.timed_out:
            raise QueryError(f"{db_path}: the query ran longer than its time limit of "
                             f"{time_limit_s:g} s (--time-limit-s); stopped") from None
        raise
    except duckdb.PermissionException as exc:
        raise QueryError(f"{db_path}: {_first_line(exc)} ({_FILES_HINT})") from None
    except duckdb.Error as exc:
        raise QueryError(f"{db_path}: {_first_line(exc)}") from None
    finally:
        if con is not None:
            con.close()


def check_statements(sql: str) -> None:
    """QueryError unless ``sql`` holds a statement: empty SQL, only ``;`` or only comments
    ran nothing and printed nothing, exit 0 (DuckDB's parser decides what a statement is; SQL it
    cannot parse is left to the query, whose error names the database)."""
    import duckdb

    try:
        statements = duckdb.extract_statements(sql)
    except duckdb.Error:
        return
    if not statements:
        raise QueryError(f"SQL {_shortened(sql)}: holds no statement (only blanks, ';' or "
                         "comments); give a query")


def _shortened(sql: str, keep: int = 40) -> str:
    """``sql`` as a quoted literal, elided past ``keep`` characters."""
    return repr(sql if len(sql) <= keep else f"{sql[:keep]}...")


class _Stopper:
    """While a statement runs (``with``): interrupt it past ``time_limit_s`` (``timed_out``),
    or when SIGINT, SIGTERM or SIGHUP arrive (main thread only; an ignored signal stays
    ignored), whose handler then runs once the statement has stopped. Once asked to stop it
    interrupts the connection every ``REPEAT_S`` until the block ends: an interrupt that comes
    before DuckDB has started executing (while it binds) would be lost. ``con``, the connection
    to interrupt, is set once open: a signal before that stops its first statement."""

    SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
    REPEAT_S = 0.05

    def __init__(self, time_limit_s: float) -> None:
        self.con: duckdb.DuckDBPyConnection | None = None
        self.timed_out = False
        self.received: int | None = None
        self.timer = threading.Timer(time_limit_s, self._time_out)
        self.previous: dict[int, Any] = {}
        self.done = threading.Event()
        self.stopping: threading.Thread | None = None

    def _time_out(self) -> None:
        self.timed_out = True
        self._stop()

    def _on_signal(self, signum: int, frame: object) -> None:
        self.received = self.received or signum
        self._stop()

    def _stop(self) -> None:
        if self.stopping is None:
            self.stopping = threading.Thread(target=self._interrupt_until_done, daemon=True,
                                             name="query-stop")
            self.stopping.start()

    def _interrupt_until_done(self) -> None:
        while True:
            if self.con is not None:
                self.con.interrupt()
            if self.done.wait(self.REPEAT_S):
                return

    def __enter__(self) -> _Stopper:
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                sig = getattr(signal, name, None)
                if sig is not None and signal.getsignal(sig) not in (signal.SIG_IGN, None):
                    self.previous[sig] = signal.signal(sig, self._on_signal)
        self.timer.daemon = True
        self.timer.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.timer.cancel()
        self.done.set()
        if self.stopping is not None:
            self.stopping.join()
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        if self.received is not None:  # its own handler now (Ctrl-C: KeyboardInterrupt)
            signal.raise_signal(self.received)


def open_sandbox(db_path: Path, tables: Mapping[str, str | Path]) -> duckdb.DuckDBPyConnection:
    """A read-only connection to ``db_path`` with the ``tables`` views, external access off,
    spilling to disk off (no temporary folder the SQL could reach) and the configuration
    locked (no SQL can turn any of it back on)."""
    import duckdb

    try:
        con = duckdb.connect(str(db_path), read_only=True, config={
            "autoinstall_known_extensions": False, "autoload_known_extensions": False})
    except duckdb.Error as exc:
        raise InputError(f"{db_path}: not a readable DuckDB database "
                         f"({_first_line(exc)})") from None
    try:
        existing = {r[0] for r in con.execute(
            "SELECT table_name FROM information_schema.tables").fetchall()}
        for name, path in tables.items():
            if not _NAME.fullmatch(name) or name.lower() in {e.lower() for e in existing}:
                raise ConfigError(f"--table {name}={path}: the name must be a new SQL identifier "
                                  f"(not one of the database's tables or views)")
            con.register(name, _parquet_dataset(Path(path)))
        con.execute("SET temp_directory = ''")  # before the next line, which allows it
        con.execute("SET enable_external_access = false")
        con.execute("SET lock_configuration = true")
    except BaseException:
        con.close()
        raise
    return con


def _parquet_dataset(path: Path) -> Any:
    """A pyarrow dataset over a Parquet file or folder; InputError names the file."""
    import pyarrow.dataset as ds

    if not path.is_dir():
        input_file(path, "Parquet file")
    try:
        return ds.dataset(path, format="parquet")
    except (pa.ArrowException, OSError) as exc:
        raise InputError(f"{path}: not a readable Parquet file ({_first_line(exc)})") from None


def _check_out(out: Path, db_path: Path, tables: Mapping[str, str | Path]) -> None:
    """ConfigError when ``out`` would replace the database or an input table."""
    for source in (db_path, *map(Path, tables.values())):
        if out.resolve() == source.resolve():
            raise ConfigError(f"--out {out}: is an input of the query ({source}); "
                              f"choose another file")


def render(table: pa.Table, fmt: str) -> bytes:
    """``table`` as Parquet bytes (zstd) or UTF-8 text in one of the text formats."""
    if fmt == "parquet":
        import pyarrow.parquet as pq

        sink = pa.BufferOutputStream()
        pq.write_table(table, sink, compression="zstd")
        return sink.getvalue().to_pybytes()
    text = {"table": format_table, "csv": format_csv, "json": format_json}[fmt](table)
    return (text if not text or text.endswith("\n") else text + "\n").encode()


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


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
