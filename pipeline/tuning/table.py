"""The trials table of one study (docs/design.md), which is also the resume state.

``<OUT>/trials/algorithm=<A>/sequence=<S>/trials.parquet`` (schemas.arrow.trials_schema), one
row per finished trial sorted by trial id, rewritten atomically after every finished trial.
The study's fingerprint (``pipeline.tuning.fingerprint``: adapter, options, parameter space,
seed, ...) travels in the file's schema metadata under ``adaptune.study`` (``read_study``): the
one home of the parameter space a study searched, for every later stage. Where the table lives
(``trials_path``) and the joint study's name (``JOINT``) are the trials output layout of
``pipeline.tuning.layout``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import InputError, SchemaError
from pipeline.io_utils import atomic_path
from pipeline.odometry.base import ParameterSpace
from pipeline.tuning.job import TrialResult
from pipeline.tuning.layout import JOINT_SEQUENCE as JOINT
from pipeline.tuning.layout import trials_table_path as trials_path
from schemas.arrow import LEGACY_TRIALS_COLUMNS, check_schema_version, trials_schema

__all__ = ["JOINT", "STUDY_KEY", "read_space", "read_study", "read_trials", "trials_path",
           "write_trials"]


STUDY_KEY = b"adaptune.study"
"""Schema metadata key of the study fingerprint (JSON)."""


def write_trials(path: str | Path, space: ParameterSpace, results: Iterable[TrialResult],
                 study: Mapping[str, Any]) -> None:
    """Write the finished ``results`` (sorted by trial) as the trials table, with the study's
    fingerprint, atomically."""
    rows = sorted(results, key=lambda r: r.trial)
    names = space.names
    cols: list[pa.Array] = [
        pa.array([r.trial for r in rows], pa.int32()),
        pa.array([r.status for r in rows], pa.string()),
        pa.array([r.error for r in rows], pa.string()),
        pa.array([r.objective for r in rows], pa.float64()),
        pa.array([r.seed for r in rows], pa.int64()),
        pa.array([json.dumps({n: r.params[n] for n in names}) for r in rows], pa.string()),
    ]
    cols += [pa.array([r.params[n] for r in rows], pa.float64()) for n in names]
    schema = trials_schema(names)
    schema = schema.with_metadata({**schema.metadata, STUDY_KEY: json.dumps(study).encode()})
    table = pa.Table.from_arrays(cols, schema=schema)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def read_study(path: str | Path) -> dict[str, Any] | None:
    """The study fingerprint stored with the trials table at ``path``; None when there is no
    table, or it has none (an older one)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        meta = pq.read_schema(path).metadata or {}
    except (pa.ArrowInvalid, OSError) as exc:
        raise InputError(f"{path}: not a readable trials table ({exc}); "
                         "delete it to start over") from exc
    if STUDY_KEY not in meta:
        return None
    try:
        study = json.loads(meta[STUDY_KEY])
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: its study fingerprint is not JSON ({exc})") from None
    return study if isinstance(study, dict) else None


def read_space(out_dir: str | Path, algorithm: str) -> ParameterSpace:
    """The parameter space the studies of ``algorithm`` in the trials folder ``out_dir``
    searched (from their fingerprints); InputError when there is none, or they disagree."""
    out_dir = Path(out_dir)
    tables = sorted(trials_path(out_dir, algorithm, "*").parent.parent.glob(
        "sequence=*/trials.parquet"))
    spaces = {}
    for table in tables:
        study = read_study(table)
        if study is None or not isinstance(study.get("space"), list):
            raise InputError(f"{table}: no parameter space stored with it (written by an older "
                             "adaptune); run the trials again")
        spaces[table] = study["space"]
    if not spaces:
        raise InputError(f"{out_dir}: no trials of {algorithm!r} to read the parameter space of")
    first, *rest = spaces.items()
    for table, space in rest:
        if space != first[1]:
            raise InputError(f"{table}: searched another parameter space than {first[0]}")
    return ParameterSpace.from_json(first[1], str(first[0]))


def read_trials(path: str | Path, space: ParameterSpace) -> list[TrialResult]:
    """Finished trials of an earlier run ([] when there is no table yet); their wall time is
    NaN (the table does not keep it).

    SchemaError when the table was written for other parameters (another algorithm version).
    """
    path = Path(path)
    if not path.is_file():
        return []
    try:
        table = pq.read_table(path)
    except (pa.ArrowInvalid, OSError) as exc:
        raise InputError(f"{path}: not a readable trials table ({exc}); "
                         "delete it to start over") from exc
    check_schema_version(table.schema, str(path))
    table = table.drop_columns([c for c in LEGACY_TRIALS_COLUMNS if c in table.column_names])
    expected = trials_schema(space.names)
    if table.schema.names != expected.names:
        raise SchemaError(f"{path}: columns {table.schema.names} do not match the parameters "
                          f"{space.names}; delete it to start over")
    d = table.to_pydict()
    return [TrialResult(trial=d["trial"][i], status=d["status"][i], error=d["error"][i],
                        objective=d["objective"][i], wall_time_s=math.nan,
                        seed=d["seed"][i], params={n: d[f"p_{n}"][i] for n in space.names})
            for i in range(table.num_rows)]
