"""Arrow schemas of every Parquet table adaptune writes (schema version in the metadata)."""

from __future__ import annotations

import pyarrow as pa

from schemas import SCHEMA_VERSION

POSE_COLUMNS = [f"T_{r}{c}" for r in range(3) for c in range(4)]
"""The 12 numbers of T_world_lidar, row-major 3x4: T_00 .. T_23."""

_META = {b"adaptune.schema_version": SCHEMA_VERSION.encode()}

TRAJECTORY = pa.schema(
    [pa.field("frame", pa.int32(), nullable=False),
     pa.field("stamp_ns", pa.int64(), nullable=False)]
    + [pa.field(c, pa.float64(), nullable=False) for c in POSE_COLUMNS],
    metadata={**_META, b"adaptune.table": b"trajectory"},
)
"""One trial's estimated trajectory: T_world_lidar per frame."""

FRAME_KEY = [pa.field("sequence", pa.string(), nullable=False),
             pa.field("frame", pa.int32(), nullable=False)]
"""The columns that name a frame of a data set."""


def descriptors_schema(width: int, descriptor_json: str = "") -> pa.Schema:
    """The descriptor of every frame: sequence, frame, stamp_ns, then ``width`` float32 values
    d0 .. d<width-1> (the descriptor's ``size``; 90 for the default NDT histogram). The
    descriptor's settings (its JSON) go into the metadata as ``adaptune.descriptor``."""
    meta = {**_META, b"adaptune.table": b"descriptors"}
    if descriptor_json:
        meta[b"adaptune.descriptor"] = descriptor_json.encode()
    return pa.schema(
        [*FRAME_KEY, pa.field("stamp_ns", pa.int64(), nullable=False)]
        + [pa.field(f"d{i}", pa.float32(), nullable=False) for i in range(width)],
        metadata=meta,
    )


def environment_schema(dim: int) -> pa.Schema:
    """The environment E of every frame: sequence, frame, then ``dim`` float32 values
    e0 .. e<dim-1> (the PCA's dimension, params ``descriptors.pca_dim``)."""
    return pa.schema(
        FRAME_KEY + [pa.field(f"e{i}", pa.float32(), nullable=False) for i in range(dim)],
        metadata={**_META, b"adaptune.table": b"environment"},
    )


SCHEDULE_BASE = pa.schema(
    [pa.field("frame", pa.int32(), nullable=False),
     pa.field("stamp_ns", pa.int64(), nullable=False)],
    metadata={**_META, b"adaptune.table": b"schedule"},
)
"""A parameter schedule: these columns plus one float64 column per parameter."""


def schedule_schema(param_names: list[str]) -> pa.Schema:
    """Schema of a schedule table for the given parameter names (float64 each)."""
    s = SCHEDULE_BASE
    for name in param_names:
        s = s.append(pa.field(name, pa.float64(), nullable=False))
    return s.with_metadata(SCHEDULE_BASE.metadata)


def check_schema_version(schema: pa.Schema, what: str) -> None:
    """Raise SchemaError when a Parquet file was written with another major schema version."""
    from pipeline.errors import SchemaError

    meta = schema.metadata or {}
    got = meta.get(b"adaptune.schema_version", b"").decode()
    if got.split(".")[0] != SCHEMA_VERSION.split(".")[0]:
        raise SchemaError(f"{what}: schema version {got or 'missing'}, "
                          f"this adaptune reads {SCHEMA_VERSION}")


TRIALS_BASE = pa.schema(
    [pa.field("trial", pa.int32(), nullable=False),
     pa.field("status", pa.string(), nullable=False),
     pa.field("error", pa.string(), nullable=False),
     pa.field("objective", pa.float64(), nullable=False),
     pa.field("seed", pa.int64(), nullable=False),
     pa.field("params_json", pa.string(), nullable=False)],
    metadata={**_META, b"adaptune.table": b"trials"},
)
"""One SMBO study's trials (docs/design.md, "Formats"): these columns plus ``p_<name>`` float64
each."""
LEGACY_TRIALS_COLUMNS = ("wall_time_s",)
"""Columns of trials tables written before schema version 1.1 that are read and dropped."""

TRIAL_STATUSES = ("ok", "failed", "pruned", "lost")
"""Values of the trials table's ``status`` column: ok (scored), failed (the odometry failed:
objective = the penalty), pruned (stopped early, hopeless: objective = its running RTE where
it stopped, its trajectory covers the frames it ran), lost (the machinery failed: objective
NaN, run again on resume)."""


def trials_schema(param_names: list[str]) -> pa.Schema:
    """Schema of ``<OUT>/trials/algorithm=<A>/sequence=<S>/trials.parquet`` for these parameters.

    Columns: trial int32, status (``TRIAL_STATUSES``), error ('' when ok), objective float64,
    seed int64, params_json (JSON object name -> value), then one float64 column ``p_<name>``
    per parameter in the given order. No wall time: a cached output holds what the code,
    params and data determine, and nothing a run's speed does (the trials stage's record
    has the times; docs/design.md, "Same numbers on every machine").
    """
    s = TRIALS_BASE
    for name in param_names:
        s = s.append(pa.field(f"p_{name}", pa.float64(), nullable=False))
    return s.with_metadata(TRIALS_BASE.metadata)
