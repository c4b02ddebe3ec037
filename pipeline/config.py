"""Typed, validated params.yaml sections under one root.

Each stage has one model (a ``Section`` subclass) next to the code that uses it; ``SECTIONS`` is
the one map from a section's name to its model. Loading a params file (``load_params``,
``load_section``) refuses unknown sections and validates every section it holds, so a typo
anywhere (``surogate:``, ``trials.iteratons``) is one line naming it, whichever stage reads the
file; errors name the value and the rule it breaks, e.g. ``trials.iterations must be >= 1,
got 0``. The models are imported by name when a file is loaded (``importlib``), not at import:
this module stays at the bottom layer, and a stage's dvc.yaml deps stay the code it runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    model_validator,
)

from pipeline.errors import ConfigError
from pipeline.selection import SelectionSettings

S = TypeVar("S", bound="Section")


class Section(BaseModel):
    """Base of every params.yaml section model: unknown keys are errors, models are frozen,
    numbers are finite (``.inf`` or ``.nan`` is no weight, period or threshold)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


MAX_ITERATIONS = 1_000_000
"""The most trials a study may run (``trials.iterations``, ``fixed.iterations``,
``--iterations``): a study's trial ids are listed up front, and a count of 22 digits grew
memory for a minute without starting a trial."""


def _iteration_count(value: Any) -> Any:
    """``value`` when it is an integer in [1, MAX_ITERATIONS]; ValueError naming the rule
    otherwise (a bool is no count, nor is 3.0: pydantic's lax mode took True as 1)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_ITERATIONS:
        raise ValueError(f"must be an integer in [1, {MAX_ITERATIONS}] (MAX_ITERATIONS), not a "
                         "bool or a float")
    return value


IterationCount = Annotated[int, BeforeValidator(_iteration_count)]
"""A number of trials: an int in [1, MAX_ITERATIONS], checked before any coercion."""


class BaseSection(Section):
    """The shared ``base`` section: the seed; L, the RTE sub-trajectory length that the
    ``trials``, ``rte``, ``evaluate`` and ``generalize`` sections take from here
    (``FROM_BASE``); and the sequence folder every stage after ``simulate`` / ``ingest`` /
    ``simulate_kitti`` reads (dvc.yaml ``${...}``): the simulated worlds, the recordings of
    the ``data`` section, or simulated KITTI (``SEQUENCE_FOLDERS``)."""

    seed: int = Field(42, ge=0)
    length_m: float = Field(25.0, gt=0)
    sequences: Literal["data/sequences", "data/recordings", "data/kitti_sim"] = "data/sequences"


SEQUENCE_FOLDERS = {"simulate": "data/sequences", "ingest": "data/recordings",
                    "simulate_kitti": "data/kitti_sim"}
"""The sequences folder each data stage of dvc.yaml writes (what ``base.sequences`` picks)."""


FROM_BASE: dict[str, tuple[str, ...]] = {
    "trials": ("length_m",),
    "evaluate": ("length_m",),
    "generalize": ("length_m",),
    "verdict": ("length_m",),
}
"""Keys that a section takes from ``base``: set once there (dvc.yaml lists ``base.length_m`` as
a param of these stages, so ``dvc exp run -S base.length_m=100`` re-runs them); a section that
sets one itself is refused, so that no copy can disagree."""
SHARED: dict[str, tuple[str, ...]] = {
    "evaluate": ("devkit",),
}
"""Whole sections that a section takes as a key of its own (``evaluate.devkit`` is the
``devkit`` section, which the ``rte`` stage reads too): set once, refused when copied."""


class SelectSection(Section):
    """params.yaml ``select``: the selector's runtime settings. Their fields, defaults and
    bounds are ``pipeline.selection.SelectionSettings`` (the runtime's own, pydantic-free
    definition and the one validator); this model hands a mapping to it once and keeps the
    result, which the stages give the ``Selector`` whole."""

    model_config = ConfigDict(extra="allow", frozen=True)
    _settings: SelectionSettings = PrivateAttr(default_factory=SelectionSettings)

    @model_validator(mode="before")
    @classmethod
    def _mapping(cls, data: Any) -> Any:
        if not isinstance(data, Mapping):
            raise ValueError(f"select must be a mapping of settings, got {data!r}")
        return data

    @model_validator(mode="after")
    def _checked(self) -> SelectSection:
        self._settings = SelectionSettings.from_mapping(self.model_dump())
        return self

    def settings(self) -> SelectionSettings:
        """The checked runtime settings."""
        return self._settings


SECTIONS: dict[str, str] = {
    "base": "pipeline.config:BaseSection",
    "simulate": "pipeline.sim.dataset:SimulateSection",
    "data": "pipeline.sources.dataset:DataSection",
    "simulate_kitti": "pipeline.sim.kitti_dataset:SimulateKittiSection",
    "descriptors": "pipeline.descriptors.dataset:DescriptorsSection",
    "trials": "pipeline.tuning.section:TrialsSection",
    "fixed": "pipeline.tuning.section:FixedSection",
    "portfolio": "pipeline.portfolio:PortfolioSection",
    "devkit": "pipeline.metrics.section:DevkitSection",
    "surrogate": "pipeline.surrogates.section:SurrogateSection",
    "select": "pipeline.config:SelectSection",
    "evaluate": "pipeline.evaluate.section:EvaluateSection",
    "generalize": "studies.generalization.suite:GeneralizeSection",
    "verdict": "studies.verdict.section:VerdictSection",
    "real": "studies.real.section:RealSection",
}
"""Every params.yaml section: name -> ``module:Model``, in the order of params.yaml."""


RENAMED: dict[str, str] = {
    "ingest": "its KITTI data set is now a kitti source of the data section: data: {sources: "
              "[{kind: kitti, path: ROOT, sequences: [...], split: train}, ...]}",
}
"""Sections that are gone, and where their settings went (said when a file still has one)."""


def section_model(name: str) -> type[Section]:
    """The model of section ``name``; ConfigError naming an unknown section and the known."""
    ref = SECTIONS.get(name)
    if ref is None:
        raise ConfigError(f"unknown params section {name!r} (known: {', '.join(SECTIONS)})")
    module, attr = ref.split(":")
    model: type[Section] = getattr(importlib.import_module(module), attr)
    return model


def section_defaults(name: str) -> Any:
    """Section ``name`` at the code's defaults, as it is written in a params file (JSON
    types; without the keys it takes from ``base`` or another section)."""
    if name == "select":
        return SelectionSettings().to_json()
    skip = {*FROM_BASE.get(name, ()), *SHARED.get(name, ())}
    data = section_model(name)().model_dump(mode="json")
    return {k: v for k, v in data.items() if k not in skip}


def format_validation_error(section: str, exc: ValidationError) -> str:
    """One line per broken rule: ``section.field: message, got value``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in (section, *err["loc"]) if p != "")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown parameter"
        got = err.get("input")
        if msg.startswith(f"{loc}."):  # the message names its own field (select's settings)
            lines.append(msg)
        else:
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
    from pipeline.json_yaml import parse_yaml

    path = Path(path)
    text = read_input_text(path, "params file", error=ConfigError, strict=True)
    data = parse_yaml(text, str(path), error=ConfigError)
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: params file must be a mapping of sections")
    return data


def load_section(path: str | Path | None, section: str, model: type[S]) -> S:
    """Section ``section`` of the params file at ``path``, validated as ``model``, after the
    whole file is checked (``check_params``: unknown sections and keys, every section's rules).

    The keys ``FROM_BASE`` names for the section come from the validated ``base`` section;
    ``path`` None gives the section's defaults.
    """
    params = read_params(path)
    check_params(params, where=str(path) if path is not None else "params")
    return validate_section(model, section, section_data(params, section))


def load_params(path: str | Path | None) -> dict[str, Section]:
    """Every section of the params file at ``path`` (the defaults for those it leaves out),
    validated; ConfigError naming an unknown section or key, or a rule a value breaks."""
    params = read_params(path)
    check_params(params, where=str(path) if path is not None else "params")
    return {name: validate_section(section_model(name), name, section_data(params, name))
            for name in SECTIONS}


def check_params(params: Mapping[str, Any], where: str = "params") -> None:
    """ConfigError unless every section of ``params`` is known and valid (the root model:
    one line naming the first unknown section, or the section's own error)."""
    unknown = [name for name in params if name not in SECTIONS]
    if unknown:
        moved = f"; {RENAMED[unknown[0]]}" if unknown[0] in RENAMED else ""
        raise ConfigError(f"{where}: unknown params section {unknown[0]!r} (known: "
                          f"{', '.join(SECTIONS)}){moved}")
    for name in params:
        validate_section(section_model(name), name, section_data(dict(params), name))


def section_data(params: dict[str, Any], section: str) -> Any:
    """The raw data of ``section`` with the keys it takes from ``base`` and the sections it
    shares (``FROM_BASE``, ``SHARED``) filled in.

    ConfigError when the section sets such a key itself.
    """
    data = params.get(section)
    keys, shared = FROM_BASE.get(section, ()), SHARED.get(section, ())
    if not (keys or shared) or (data is not None and not isinstance(data, dict)):
        return data
    data = dict(data or {})
    for key, home in [*((k, f"base.{k}") for k in keys), *((k, k) for k in shared)]:
        if key in data:
            raise ConfigError(f"{section}.{key}: set once in {home}, not per section, "
                              f"got {data[key]!r}")
    base = validate_section(BaseSection, "base", params.get("base")) if keys else None
    return {**data, **{key: getattr(base, key) for key in keys},
            **{name: params.get(name) or {} for name in shared}}
