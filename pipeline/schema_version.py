"""The check every reader of adaptune's Parquet tables makes: the major schema version
(``schemas.SCHEMA_VERSION``) the file was written with is this adaptune's."""

from __future__ import annotations

import pyarrow as pa

from pipeline.errors import SchemaError
from schemas import SCHEMA_VERSION


def check_schema_version(schema: pa.Schema, what: str) -> None:
    """Raise SchemaError when a Parquet file was written with another major schema version."""
    meta = schema.metadata or {}
    got = meta.get(b"adaptune.schema_version", b"").decode()
    if got.split(".")[0] != SCHEMA_VERSION.split(".")[0]:
        raise SchemaError(f"{what}: schema version {got or 'missing'}, "
                          f"this adaptune reads {SCHEMA_VERSION}")
