"""The training rows of the surrogate: q_ij = [E_i, x_j] -> y_ij, read from the results
database (its ``surrogate_rows`` view, or ``portfolio_rows`` for the portfolio selector;
docs/design.md, "Formats")."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError


@dataclass
class TrainingRows:
    """The rows q_ij = [E_i, x_j] -> y_ij of one algorithm, as plain arrays.

    E: (M, D) environment values; U: (M, P) parameters mapped to [0, 1] (``UnitCube``);
    y: (M,) RTE [%]; sequences: (M,) str; frames: (M,) int; trials: (M,) int.
    """

    E: NDArray[np.float64]
    U: NDArray[np.float64]
    y: NDArray[np.float64]
    sequences: NDArray[np.str_]
    frames: NDArray[np.int64]
    trials: NDArray[np.int64]

    def __post_init__(self) -> None:
        m = len(self.y)
        if m == 0:
            raise InputError("no surrogate rows (no ok trials with per-frame RTE and environment)")
        for name in ("E", "U", "sequences", "frames", "trials"):
            if len(getattr(self, name)) != m:
                raise InputError(
                    f"surrogate rows: {name} has {len(getattr(self, name))} rows, y has {m}"
                )
        bad = ~np.isfinite(self.y) | ~np.isfinite(self.E).all(1) | ~np.isfinite(self.U).all(1)
        if bad.any():
            raise InputError(f"surrogate rows: {int(bad.sum())} rows with NaN/inf values")


ROW_VIEWS = {"trials": "surrogate_rows", "portfolio": "portfolio_rows"}
"""params ``surrogate.rows`` -> the database view its rows come from (schemas/views.sql)."""


def read_training_rows(
    db_path: str | Path, algorithm: str | None, space_of: Callable[[str], Any],
    source: str = "trials",
) -> tuple[str, list[dict[str, Any]], TrainingRows]:
    """Rows of the view of ``source`` (``ROW_VIEWS``) of ``db_path`` for ``algorithm`` (None:
    the only one in the view). ``space_of(name)`` -> ParameterSpace. Returns (algorithm, space
    json, rows)."""
    import duckdb

    db_path = Path(db_path)
    if not db_path.is_file():
        raise InputError(f"{db_path}: no such results database (built by the rte stage)")
    try:
        con = duckdb.connect(str(db_path), read_only=True)
    except duckdb.Error as exc:
        raise InputError(f"{db_path}: not a DuckDB database ({exc})") from None
    try:
        view = ROW_VIEWS[source]
        algorithm = _choose_algorithm(con, db_path, algorithm, view)
        space = space_of(algorithm)
        cols = [r[0] for r in con.execute(f"DESCRIBE {view}").fetchall()]
        e_cols = sorted(
            (c for c in cols if c[0] == "e" and c[1:].isdigit()), key=lambda c: int(c[1:])
        )
        p_cols = [f"p_{n}" for n in space.names]
        missing = [c for c in p_cols if c not in cols]
        if missing:
            raise InputError(f"{db_path}: {view} has no column {missing[0]}")
        sql = (
            f"SELECT sequence, trial, frame, {', '.join(e_cols)}, {', '.join(p_cols)}, y "
            f"FROM {view} WHERE algorithm = ? AND y IS NOT NULL "
            "ORDER BY sequence, frame, trial"
        )
        table = con.execute(sql, [algorithm]).fetchnumpy()
    finally:
        con.close()
    E = np.column_stack([np.asarray(table[c], np.float64) for c in e_cols])
    X = np.column_stack([np.asarray(table[c], np.float64) for c in p_cols])
    rows = TrainingRows(
        E,
        space.unit_cube.to_unit(X),
        np.asarray(table["y"], np.float64),
        np.asarray(table["sequence"]).astype(str),
        np.asarray(table["frame"], np.int64),
        np.asarray(table["trial"], np.int64),
    )
    return algorithm, space.to_json(), rows


def _choose_algorithm(con: Any, db_path: Path, algorithm: str | None, view: str) -> str:
    """``algorithm``, or the only one of the view; errors name what the view holds."""
    import duckdb

    try:
        algos = [
            r[0]
            for r in con.execute(
                f"SELECT DISTINCT algorithm FROM {view} ORDER BY 1"
            ).fetchall()
        ]
    except duckdb.Error as exc:
        raise InputError(
            f"{db_path}: no {view} view ({str(exc).splitlines()[0]})"
        ) from None
    if algorithm is None:
        if len(algos) != 1:
            raise ConfigError(
                f"{db_path}: {view} holds algorithms {algos}; choose one with --algorithm"
            )
        return str(algos[0])
    if algorithm not in algos:
        raise InputError(
            f"{db_path}: no surrogate rows for algorithm {algorithm!r} "
            f"(have: {', '.join(algos) or 'none'})"
        )
    return algorithm
