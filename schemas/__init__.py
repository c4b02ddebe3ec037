"""Contracts between stages: ROS 2 message texts, Arrow schemas, DuckDB DDL, JSON Schemas.

Every schema carries a version; readers refuse files written with another major version.
"""

from __future__ import annotations

from pathlib import Path

SCHEMA_VERSION = "1.1"
"""Version of every on-disk format adaptune writes (MCAP metadata, Parquet, DuckDB, artifact)."""

SCHEMA_DIR = Path(__file__).resolve().parent


def schema_path(name: str) -> Path:
    """Absolute path of a file in the schemas package, e.g. ``schema_path("rte.sql")``."""
    return SCHEMA_DIR / name


def read_text(name: str) -> str:
    """Text of a file in the schemas package."""
    return schema_path(name).read_text(encoding="utf-8")
