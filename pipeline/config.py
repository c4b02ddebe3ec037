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
    """Base of every params.yaml section model: unknown keys are errors, models are frozen,
    numbers are finite (``.inf`` or ``.nan`` is no weight, period or threshold)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class BaseSection(Section):
    """The shared ``base`` section: the seed; L, the RTE sub-trajectory length that the
    ``trials``, ``rte``, ``evaluate`` and ``generalize`` sections take from here
    (``FROM_BASE``); and the sequence folder every stage after ``simulate`` / ``ingest``
    reads (dvc.yaml ``${...}``)."""

    seed: int = Field(0, ge=0)
    length_m: float = Field(25.0, gt=0)
    sequences: Literal["data/sequences", "data/kitti", "data/kitti_sim"] = "data/sequences"


FROM_BASE: dict[str, tuple[str, ...]] = {
    "trials": ("length_m",),
    "rte": ("length_m",),
    "evaluate": ("length_m",),
    "generalize": ("length_m",),
}
"""Keys that a section takes from ``base``: set once there (dvc.yaml lists ``base.length_m`` as
a param of these stages, so ``dvc exp run -S base.length_m=100`` re-runs them); a section that
sets one itself is refused, so that no copy can disagree."""


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


def read_params(path: str | Path | None) -> dict[str, Any]:
    """The whole params.yaml as a dict ({} for None: every section at its defaults);
    ConfigError when missing, not a regular file of at most 64 MiB (a FIFO or /dev/zero is
    refused at once), not UTF-8 YAML or not a mapping."""
    if path is None:
        return {}
    from pipeline.io_utils import read_input_text

    path = Path(path)
    text = read_input_text(path, "params file", error=ConfigError, strict=True)
    try:
        loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: 10x faster
        data = yaml.load(text, Loader=loader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: params file must be a mapping of sections")
    return data


def load_section(path: str | Path | None, section: str, model: type[S]) -> S:
    """Read ``section`` of the params file at ``path`` and validate it as ``model``.

    The keys ``FROM_BASE`` names for the section come from the validated ``base`` section;
    ``path`` None gives the section's defaults.
    """
    return validate_section(model, section, section_data(read_params(path), section))


def section_data(params: dict[str, Any], section: str) -> Any:
    """The raw data of ``section`` with the keys it takes from ``base`` filled in.

    ConfigError when the section sets such a key itself.
    """
    data = params.get(section)
    keys = FROM_BASE.get(section, ())
    if not keys or (data is not None and not isinstance(data, dict)):
        return data
    data = dict(data or {})
    for key in keys:
        if key in data:
            raise ConfigError(f"{section}.{key}: set once in base.{key}, not per section, "
                              f"got {data[key]!r}")
    base = validate_section(BaseSection, "base", params.get("base"))
    return {**data, **{key: getattr(base, key) for key in keys}}
