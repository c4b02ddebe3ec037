"""The results database (results/adaptune.duckdb), built by the ``rte`` stage.

Tables and views: docs/design.md, "Formats"; their DDL is schemas/tables.sql and views.sql.
The per-start-frame RTE (``rte_frames``) and the KITTI devkit segments (``rte_kitti``) are
computed inside DuckDB over the trajectory Parquet files (read_parquet, hive partitioning) and
the ``ground_truth`` table: segment ends by an ASOF join on path distance, SE(3) errors by SQL
arithmetic on the pose columns (schemas/segments.sql). The database is built in a temporary
file and renamed into place, so a failure never leaves a half database.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pipeline.errors import InputError
from pipeline.geometry import path_distances
from pipeline.io_utils import atomic_path
from pipeline.metrics.section import DevkitSection
from pipeline.sequence_index import read_index
from pipeline.tuning.layout import JOINT_SEQUENCE, TRIALS_GLOB, read_trials_tables
from schemas import read_text
from schemas.arrow import POSE_COLUMNS

if TYPE_CHECKING:
    import duckdb

log = logging.getLogger(__name__)

STUDIES = ("trials", "fixed", "portfolio")
"""Names of the trials outputs the database takes (per-sequence SMBO, joint SMBO, the
portfolio study: ``pipeline.portfolio``)."""


@dataclass
class DatabaseSummary:
    """What ``build_database`` put into the database, and how long each step took [s]."""

    sequences: int = 0
    trials: int = 0
    trajectories: int = 0
    rte_frames: int = 0
    rte_kitti: int = 0
    timings_s: dict[str, float] = field(default_factory=dict)


def build_database(db_path: str | Path, sequences_dir: str | Path, studies: Mapping[str, Path],
                   length_m: float, devkit: DevkitSection, descriptors: Path | None = None,
                   environment: Path | None = None,
                   sequences: Collection[str] | None = None) -> DatabaseSummary:
    """Build the results database at ``db_path`` atomically.

    sequences_dir: data/sequences (``*.mcap`` and optionally index.json with the splits);
    length_m: L of the rte_frames segments [m] (params ``base.length_m``) of every sequence
    without an L of its own (``SequenceInfo.length_m``, which wins); devkit: the
    rte_kitti segments (params ``devkit``);
    studies: study name ('trials' | 'fixed' | 'portfolio') -> its trials output folder
    (pipeline.tuning.layout);
    descriptors / environment: the descriptor Parquet files, or None for empty tables;
    sequences: the names of the sequences (and their trials) to hold, None: every one (a study
    of a fold trains on some of a folder's sequences only).
    """

    unknown = sorted(set(studies) - set(STUDIES))
    if unknown:
        raise InputError(f"unknown study names {unknown}; known: {list(STUDIES)}")
    for what, path in (("descriptors", descriptors), ("environment", environment)):
        if path is not None and not Path(path).is_file():
            raise InputError(f"{path}: no such {what} file")
    summary = DatabaseSummary()
    with atomic_path(db_path) as tmp:
        tmp.unlink()
        con = _connect_for_build(tmp)
        try:
            steps = [
                ("tables", lambda: apply_sql(con, "tables.sql")),
                ("sequences", lambda: load_sequences(con, Path(sequences_dir), sequences)),
                ("trials", lambda: load_trials(con, studies, sequences)),
                ("trajectories", lambda: load_trajectories(con, studies, sequences)),
                ("rte_frames", lambda: score_frames(con, length_m)),
                ("rte_kitti", lambda: score_kitti(con, devkit.lengths_m, devkit.step_frames)),
                ("summary", lambda: apply_sql(con, "summary.sql")),
                ("descriptors", lambda: load_frame_table(con, "descriptors", descriptors)),
                ("environment", lambda: load_frame_table(con, "environment", environment)),
                ("views", lambda: apply_sql(con, "views.sql")),
            ]
            for name, step in steps:
                t0 = time.perf_counter()
                step()
                summary.timings_s[name] = time.perf_counter() - t0
            count_rows(con, summary)
            con.execute("DROP TABLE IF EXISTS est; CHECKPOINT")
        finally:
            con.close()
            Path(f"{tmp}.wal").unlink(missing_ok=True)
    return summary


CATALOG = "results"
"""The name the database is built under (a fixed one: DuckDB stores it in the file, and the
temporary file's name is random)."""
STORAGE_VERSION = "v1.3.0"
"""DuckDB's storage format the database is written in: the newest that stores no random bytes
(from v1.4 on the file header holds a random database identifier)."""


def _connect_for_build(path: Path) -> duckdb.DuckDBPyConnection:
    """A connection that builds the database file ``path`` byte for byte the same from the same
    inputs (docs/design.md, "Same numbers on every machine"): one thread (a parallel aggregate
    or insert orders its sums and rows by which thread came first), a fixed catalog name and a
    storage format without random bytes."""
    import duckdb

    con = duckdb.connect(config={"threads": 1})
    con.execute(f"ATTACH {sql_literal(str(path))} AS {CATALOG} "
                f"(STORAGE_VERSION {sql_literal(STORAGE_VERSION)})")
    con.execute(f"USE {CATALOG}")
    return con


def apply_sql(con: duckdb.DuckDBPyConnection, name: str) -> None:
    """Run the statements of schemas/<name>."""
    con.execute(read_text(name))


def sql_literal(text: str) -> str:
    """``text`` as a SQL string literal."""
    return "'" + text.replace("'", "''") + "'"


# ---------------------------------------------------------------------------- sequences


def load_sequences(con: duckdb.DuckDBPyConnection, sequences_dir: Path,
                   names: Collection[str] | None = None) -> None:
    """Fill sequences, frame_labels and ground_truth from every ``*.mcap`` in ``sequences_dir``
    (``names``: of those only), and the temporary table ``own_lengths`` (sequence, length_m)
    with the RTE length of every sequence that has one of its own (``score_frames``)."""
    from pipeline.sequence import SequenceReader

    con.execute("CREATE OR REPLACE TEMP TABLE own_lengths (sequence VARCHAR, length_m DOUBLE)")
    if not sequences_dir.is_dir():
        raise InputError(f"{sequences_dir}: no such sequences directory")
    splits = read_index(sequences_dir, missing_ok=True).split_of()
    paths = [p for p in sorted(sequences_dir.glob("*.mcap")) if names is None or p.stem in names]
    if not paths:
        log.warning("%s: no sequence MCAP files", sequences_dir)
    for path in paths:
        name = path.stem
        with SequenceReader(path) as reader:
            info, stamps_ns, gt = reader.info, reader.stamps_ns, reader.ground_truth()
        labels: list[tuple[int, int, str]] = [(x.start, x.end, x.label) for x in info.labels]
        con.execute("INSERT INTO sequences VALUES (?, ?, ?, ?, ?, ?, ?)",
                    [name, str(path), len(stamps_ns), info.sensor, info.source,
                     splits.get(name), json.dumps(labels)])
        insert_arrow(con, "frame_labels", frame_label_table(name, len(stamps_ns), labels))
        if info.length_m is not None:
            con.execute("INSERT INTO own_lengths VALUES (?, ?)", [name, info.length_m])
        if gt is None:
            log.warning("%s: no ground truth; its trials cannot be scored", path)
            continue
        insert_arrow(con, "ground_truth", ground_truth_table(name, stamps_ns, gt))


def frame_label_table(sequence: str, n_frames: int, labels: list[tuple[int, int, str]]
                      ) -> pa.Table:
    """Arrow rows of the frame_labels table for one sequence of ``n_frames`` frames: every
    frame inside a label's range [start, end] (inclusive) with that label; where ranges overlap
    (a boundary frame) the later label wins. Built in numpy: DuckDB's ``executemany`` took a
    minute over a tuning suite's 25,000 frames."""
    of_frame = np.full(n_frames, None, dtype=object)
    for start, end, label in labels:
        first, stop = max(start, 0), min(end + 1, n_frames)
        if stop > first:
            of_frame[first:stop] = label
    frames = np.flatnonzero(of_frame != None)  # noqa: E711 - elementwise test for None
    return pa.table({"sequence": pa.array([sequence] * len(frames), pa.string()),
                     "frame": pa.array(frames.astype(np.int32)),
                     "label": pa.array(of_frame[frames].tolist(), pa.string())})


def ground_truth_table(sequence: str, stamps_ns: np.ndarray, gt: np.ndarray) -> pa.Table:
    """Arrow rows of the ground_truth table for one sequence."""
    flat = gt[:, :3, :].reshape(-1, 12)
    cols: dict[str, Any] = {
        "sequence": pa.array([sequence] * len(gt), pa.string()),
        "frame": pa.array(np.arange(len(gt), dtype=np.int32)),
        "stamp_ns": pa.array(np.asarray(stamps_ns, np.int64)),
        "dist_m": pa.array(path_distances(gt)),
    }
    cols.update({c: pa.array(flat[:, i]) for i, c in enumerate(POSE_COLUMNS)})
    return pa.table(cols)


def insert_arrow(con: duckdb.DuckDBPyConnection, table: str, rows: pa.Table) -> None:
    """INSERT the Arrow table ``rows`` into ``table`` by column name."""
    con.register("arrow_rows", rows)
    try:
        con.execute(f"INSERT INTO {table} BY NAME SELECT * FROM arrow_rows")
    finally:
        con.unregister("arrow_rows")


# ------------------------------------------------------------------------------- trials


def load_trials(con: duckdb.DuckDBPyConnection, studies: Mapping[str, Path],
                names: Collection[str] | None = None) -> None:
    """Fill ``trials`` from every study's trials tables (``names``: their rows of those
    sequences and of joint studies only); add p_<name> and summary columns. InputError when a
    study's folder holds no trials table (its trials would be dropped from the database
    without a word)."""
    tables = {study: of_sequences(read_trials_tables(out), names)
              for study, out in studies.items()}
    for study, table in tables.items():
        if not table.num_rows:
            raise InputError(f"{studies[study]}: no trials in this {study} folder (no "
                             f"{TRIALS_GLOB}); give the folder `adaptune trials` wrote, or "
                             f"leave --{study} out")
    params = sorted({c for t in tables.values() for c in t.column_names if c.startswith("p_")})
    for name in params:
        con.execute(f'ALTER TABLE trials ADD COLUMN "{name}" DOUBLE')
    con.execute("ALTER TABLE trials ADD COLUMN mean_rte_pct DOUBLE")
    con.execute("ALTER TABLE trials ADD COLUMN rte_frames INTEGER DEFAULT 0")
    for study, table in tables.items():
        if table.num_rows:
            study_col = pa.array([study] * table.num_rows, pa.string())
            insert_arrow(con, "trials", table.add_column(0, "study", study_col))


# ------------------------------------------------------------------------- trajectories


def of_sequences(table: pa.Table, names: Collection[str] | None) -> pa.Table:
    """The rows of a trials table of the sequences ``names`` and of joint studies (all: None)."""
    if names is None:
        return table
    import pyarrow.compute as pc

    keep = pc.is_in(table.column("sequence"), pa.array([*names, JOINT_SEQUENCE], pa.string()))
    return table.filter(keep)


def load_trajectories(con: duckdb.DuckDBPyConnection, studies: Mapping[str, Path],
                      names: Collection[str] | None = None) -> None:
    """Temporary table ``est`` of every trajectory of every study (``names``: of those
    sequences and joint studies only), validated against the data."""
    parts = []
    for study, out in studies.items():
        traj_dir = Path(out) / "trajectories"
        pattern = "algorithm=*/sequence=*/trial=*/trajectory.parquet"
        if not any(traj_dir.glob(pattern)):
            log.warning("%s: no trajectories", traj_dir)
            continue
        glob = sql_literal(str(traj_dir / "**" / "*.parquet"))
        parts.append(
            f"SELECT {sql_literal(study)} AS study, algorithm, sequence, trial, frame, "
            f"{', '.join(POSE_COLUMNS)}, filename "
            f"FROM read_parquet({glob}, hive_partitioning = true, filename = true, "
            "hive_types = {'algorithm': VARCHAR, 'sequence': VARCHAR, 'trial': INTEGER})"
            + ("" if names is None else " WHERE sequence IN ("
               + ", ".join(sql_literal(n) for n in [*names, JOINT_SEQUENCE]) + ")"))
    if not parts:
        cols = ", ".join(f"{c} DOUBLE" for c in POSE_COLUMNS)
        con.execute(f"CREATE TEMP TABLE est (study VARCHAR, algorithm VARCHAR, sequence VARCHAR, "
                    f"trial INTEGER, frame INTEGER, {cols}, filename VARCHAR)")
        return
    import duckdb

    try:
        con.execute("CREATE TEMP TABLE est AS " + " UNION ALL ".join(parts))
    except duckdb.Error as exc:
        raise InputError(f"trajectories: cannot read ({first_line(exc)})") from None
    check_trajectories(con)


def check_trajectories(con: duckdb.DuckDBPyConnection) -> None:
    """Raise InputError naming the first trajectory file that does not fit its sequence.

    A pruned trial's trajectory covers the frames it ran: 0..k, fewer than the sequence has.
    """
    finite = " AND ".join(f"isfinite({c})" for c in POSE_COLUMNS)
    bad = con.execute(f"""
        WITH pruned AS (SELECT DISTINCT study, algorithm, sequence, trial FROM trials
                        WHERE status = 'pruned')
        SELECT any_value(e.filename), e.sequence, any_value(s.frames), count(*),
               count(DISTINCT e.frame), min(e.frame), max(e.frame), bool_and({finite})
        FROM est AS e LEFT JOIN sequences AS s USING (sequence)
        LEFT JOIN pruned AS p ON p.study = e.study AND p.algorithm = e.algorithm
            AND p.trial = e.trial AND (p.sequence = e.sequence OR p.sequence = '__joint__')
        GROUP BY e.study, e.algorithm, e.sequence, e.trial
        HAVING any_value(s.frames) IS NULL
            OR (count(*) <> any_value(s.frames)
                AND (count(p.trial) = 0 OR count(*) > any_value(s.frames)))
            OR count(DISTINCT e.frame) <> count(*) OR min(e.frame) <> 0
            OR NOT bool_and({finite})
        LIMIT 1""").fetchone()
    if bad is None:
        return
    path, sequence, frames, n, distinct, _, _, all_finite = bad
    if frames is None:
        raise InputError(f"{path}: sequence '{sequence}' is not in the sequences directory")
    if not all_finite:
        raise InputError(f"{path}: trajectory has non-finite poses")
    if n != frames:
        raise InputError(f"{path}: trajectory has {n} poses, "
                         f"sequence '{sequence}' has {frames} frames")
    raise InputError(f"{path}: trajectory frames are not 0..{frames - 1} "
                     f"({distinct} distinct of {n})")


# -------------------------------------------------------------------------------- scores


def score_frames(con: duckdb.DuckDBPyConnection, length_m: float) -> None:
    """Fill ``rte_frames``: the segment of L metres from every frame of every trial, L the
    sequence's own (``own_lengths``, from ``load_sequences``) or else ``length_m``."""
    con.execute("CREATE OR REPLACE TEMP TABLE seg_starts AS "
                "SELECT g.sequence, g.frame, coalesce(o.length_m, ?::DOUBLE) AS length_m "
                "FROM ground_truth AS g LEFT JOIN own_lengths AS o USING (sequence)",
                [length_m])
    con.execute(f"""
        INSERT INTO rte_frames
        SELECT study, algorithm, sequence, trial, frame, end_frame, length_m,
               t_err * 100.0, degrees(r_err)
        FROM ({read_text("segments.sql")})
        ORDER BY study, algorithm, sequence, trial, frame""")


def score_kitti(con: duckdb.DuckDBPyConnection, lengths_m: tuple[float, ...],
                step_frames: int) -> None:
    """Fill ``rte_kitti``: the devkit segments (every ``step_frames`` frames, every length)."""
    if not lengths_m:
        return
    con.execute("CREATE OR REPLACE TEMP TABLE seg_starts AS "
                "SELECT sequence, frame, unnest(?::DOUBLE[]) AS length_m FROM ground_truth "
                "WHERE frame % ? = 0", [list(lengths_m), step_frames])
    con.execute(f"""
        INSERT INTO rte_kitti
        SELECT study, algorithm, sequence, trial, frame, end_frame, length_m, t_err, r_err
        FROM ({read_text("segments.sql")})
        ORDER BY study, algorithm, sequence, trial, frame, length_m""")


# ------------------------------------------------------------------- descriptor tables


VALUE_PREFIX = {"descriptors": "d", "environment": "e"}
"""The value columns of the frame tables: d0..d<F-1> (descriptor), e0..e<D-1> (environment)."""


def load_frame_table(con: duckdb.DuckDBPyConnection, table: str, path: Path | None) -> None:
    """Fill ``descriptors`` or ``environment`` from its Parquet file (left empty when None),
    with as many value columns as the file has."""
    import duckdb

    if path is None:
        return
    if not Path(path).is_file():
        raise InputError(f"{path}: no such {table} file")
    add_value_columns(con, table, path)
    columns = [r[0] for r in con.execute(f"DESCRIBE {table}").fetchall()]
    try:
        con.execute(f"INSERT INTO {table} SELECT {', '.join(columns)} "
                    f"FROM read_parquet({sql_literal(str(path))})")
    except duckdb.Error as exc:
        raise InputError(f"{path}: not a valid {table} table ({first_line(exc)})") from None


def add_value_columns(con: duckdb.DuckDBPyConnection, table: str, path: Path) -> None:
    """Give ``table`` the value columns <prefix>0..<prefix>N-1 of the Parquet file (FLOAT; the
    width is the file's, tables.sql declares none)."""
    import duckdb

    prefix = VALUE_PREFIX[table]
    try:
        file_cols = [r[0] for r in con.execute(
            f"DESCRIBE SELECT * FROM read_parquet({sql_literal(str(path))})").fetchall()]
    except duckdb.Error as exc:
        raise InputError(f"{path}: not a valid {table} table ({first_line(exc)})") from None
    values = [c for c in file_cols if c[:1] == prefix and c[1:].isdigit()]
    if values != [f"{prefix}{i}" for i in range(len(values))]:
        raise InputError(f"{path}: {table} value columns must be {prefix}0..{prefix}N-1 in "
                         f"order, got {values[:3]}...")
    for c in values:
        con.execute(f"ALTER TABLE {table} ADD COLUMN {c} FLOAT")


def count_rows(con: duckdb.DuckDBPyConnection, summary: DatabaseSummary) -> None:
    """Row counts of the main tables into ``summary``."""
    one = lambda sql: int(con.execute(sql).fetchone()[0])  # type: ignore[index]  # noqa: E731
    summary.sequences = one("SELECT count(*) FROM sequences")
    summary.trials = one("SELECT count(*) FROM trials")
    summary.trajectories = one("SELECT count(*) FROM (SELECT DISTINCT study, algorithm, "
                               "sequence, trial FROM est)")
    summary.rte_frames = one("SELECT count(*) FROM rte_frames")
    summary.rte_kitti = one("SELECT count(*) FROM rte_kitti")


def first_line(exc: BaseException) -> str:
    """The first line of an exception message."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
