"""The trials output layout (docs/design.md, "Formats"): where trajectories and trials tables
live, the joint study's name, the best trial of a study, a reader of every trials table.

``<OUT>/trajectories/algorithm=<A>/sequence=<S>/trial=<N>/trajectory.parquet`` and
``<OUT>/trials/algorithm=<A>/sequence=<S>/trials.parquet`` (S = ``__joint__`` for the joint SMBO);
a study of successive halving also posts its trials' values at the rungs under
``<OUT>/rungs/algorithm=<A>/sequence=<S>/`` (``pipeline.tuning.rung_board``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from pipeline.errors import InputError
from schemas.arrow import TRIAL_STATUSES, TRIALS_BASE, check_schema_version

JOINT_SEQUENCE = "__joint__"
"""The ``sequence`` of the joint SMBO's trials table (one x for all training sequences)."""


def best_trial(trials: Iterable[tuple[int, str, float | None]]) -> int | None:
    """The id of the best of a study's (trial, status, objective) rows: the lowest objective
    among the 'ok' trials with a finite objective, ties to the lowest trial id; None when no
    trial qualifies. The one rule for "the best trial" (the fixed parameters, the novelty
    fallback)."""
    ok = [(float(obj), int(t)) for t, status, obj in trials
          if status == "ok" and obj is not None and math.isfinite(obj)]
    return min(ok)[1] if ok else None


def trajectory_path(out_dir: str | Path, algorithm: str, sequence: str, trial: int) -> Path:
    """Path of one trial's trajectory Parquet file under ``out_dir``."""
    return (Path(out_dir) / "trajectories" / f"algorithm={algorithm}" / f"sequence={sequence}"
            / f"trial={trial}" / "trajectory.parquet")


def read_trial_trajectories(out_dir: str | Path, algorithm: str,
                            sequences: Iterable[tuple[str, Any]], trial: int
                            ) -> list[NDArray[np.float64] | None]:
    """T_world_lidar (N, 4, 4) of ``trial``'s stored trajectory on each of ``sequences``
    ((name, path) pairs; partial for a pruned trial), None where it has none."""
    from pipeline.trajectory import read_trajectory

    out: list[NDArray[np.float64] | None] = []
    for name, _ in sequences:
        path = trajectory_path(out_dir, algorithm, name, trial)
        out.append(read_trajectory(path).T_world_lidar if path.is_file() else None)
    return out


def trials_table_path(out_dir: str | Path, algorithm: str, sequence: str) -> Path:
    """Path of the trials table of one (algorithm, sequence) study under ``out_dir``."""
    return (Path(out_dir) / "trials" / f"algorithm={algorithm}" / f"sequence={sequence}"
            / "trials.parquet")


def rungs_folder(out_dir: str | Path, algorithm: str, sequence: str) -> Path:
    """Folder of one study's rung board (``pipeline.tuning.rung_board``) under ``out_dir``."""
    return Path(out_dir) / "rungs" / f"algorithm={algorithm}" / f"sequence={sequence}"


TRIALS_GLOB = "trials/algorithm=*/sequence=*/trials.parquet"
"""Where a trials output folder keeps its trials tables (one per algorithm and sequence)."""


def trials_files(out_dir: str | Path) -> list[tuple[str, str, Path]]:
    """(algorithm, sequence, path) of every trials table under ``out_dir``, sorted."""
    found = []
    for path in sorted(Path(out_dir).glob(TRIALS_GLOB)):
        algorithm = path.parent.parent.name.removeprefix("algorithm=")
        sequence = path.parent.name.removeprefix("sequence=")
        found.append((algorithm, sequence, path))
    return found


def read_trials_tables(out_dir: str | Path) -> pa.Table:
    """Every trials table under ``out_dir`` as one Arrow table.

    Columns: algorithm, sequence (from the hive path), the trials_schema base columns, then the
    union of all ``p_<name>`` columns (null where an algorithm lacks the parameter).
    Raises InputError when ``out_dir`` is missing or a file breaks the schema.
    """
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise InputError(f"{out_dir}: no such trials directory")
    tables = [_read_one(path, algorithm, sequence)
              for algorithm, sequence, path in trials_files(out_dir)]
    if not tables:
        return _empty_trials()
    merged = pa.concat_tables(tables, promote_options="default")
    base = ["algorithm", "sequence", *TRIALS_BASE.names]
    params = sorted(c for c in merged.column_names if c.startswith("p_"))
    return merged.select(base + params)


def _read_one(path: Path, algorithm: str, sequence: str) -> pa.Table:
    """One trials table with algorithm and sequence columns prepended; validated."""
    try:
        table = pq.read_table(path)
    except (pa.ArrowInvalid, OSError) as exc:
        raise InputError(f"{path}: not a readable Parquet file ({exc})") from exc
    check_schema_version(table.schema, str(path))
    for field in TRIALS_BASE:
        if field.name not in table.column_names:
            raise InputError(f"{path}: missing trials column '{field.name}'")
        if not table.schema.field(field.name).type.equals(field.type):
            raise InputError(f"{path}: column '{field.name}' is "
                             f"{table.schema.field(field.name).type}, expected {field.type}")
    extra = [c for c in table.column_names if c not in TRIALS_BASE.names and not c.startswith("p_")]
    if extra:
        raise InputError(f"{path}: unexpected trials columns {extra}")
    bad = set(table.column("status").to_pylist()) - set(TRIAL_STATUSES)
    if bad:
        raise InputError(f"{path}: status must be one of {list(TRIAL_STATUSES)}, got {sorted(bad)}")
    n = table.num_rows
    table = table.replace_schema_metadata(None)
    table = table.add_column(0, "sequence", pa.array([sequence] * n, pa.string()))
    return table.add_column(0, "algorithm", pa.array([algorithm] * n, pa.string()))


def _empty_trials() -> pa.Table:
    """A trials table without rows and without parameter columns."""
    schema = pa.schema([pa.field("algorithm", pa.string()), pa.field("sequence", pa.string()),
                        *[f.with_nullable(True) for f in TRIALS_BASE]])
    return schema.empty_table()
