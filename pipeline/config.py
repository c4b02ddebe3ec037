"""Typed, validated params.yaml sections.

Each stage has one model (a ``Section`` subclass) next to the code that uses it. ``load_section``
reads params.yaml and validates; errors name the value and the rule it breaks, e.g.
``trials.iterations must be >= 1, got 0``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.errors import ConfigError

S = TypeVar("S", bound="Section")


class Section(BaseModel):
    """Base of every params.yaml section model: unknown keys are errors, models are frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class BaseSection(Section):
    """The shared ``base`` section: the seed; L, which the ``trials``, ``rte`` and ``evaluate``
    sections take by a YAML alias (``length_m: *length_m``) so that it is set once; and the
    sequence folder every stage after ``simulate`` / ``ingest`` reads (dvc.yaml ``${...}``)."""

    seed: int = 0
    length_m: float = Field(25.0, gt=0)
    sequences: Literal["data/sequences", "data/kitti"] = "data/sequences"


def format_validation_error(section: str, exc: ValidationError) -> str:
    """One line per broken rule: ``section.field: message, got value``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in (section, *err["loc"]) if p != "")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown parameter"
        got = err.get("input")
        lines.append(f"{loc}: {msg}, got {got!r}" if "got" not in msg else f"{loc}: {msg}")
    return "; ".join(lines)


def validate_section(model: type[S], section: str, data: dict[str, Any] | None) -> S:
    """Validate ``data`` as ``model``; raise ConfigError naming the value and the rule."""
    try:
        return model.model_validate(data or {})
    except ValidationError as exc:
        raise ConfigError(format_validation_error(section, exc)) from None


def read_params(path: str | Path) -> dict[str, Any]:
    """The whole params.yaml as a dict; ConfigError when missing or not a mapping."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such params file") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: params file must be a mapping of sections")
    return data


def load_section(path: str | Path, section: str, model: type[S]) -> S:
    """Read ``section`` of the params file at ``path`` and validate it as ``model``."""
    return validate_section(model, section, read_params(path).get(section))
