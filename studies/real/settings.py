"""What the real-data study's steps read from its params file (real/params.yaml): the sections
(``StudySettings``, ``load_settings``), each run's floor inputs and an algorithm's ``trials``
(its search space and untuned options from ``real``: ``algorithm_settings``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.tuning.section import FixedSection, TrialsSection
from studies.real.section import RealSection


@dataclass(frozen=True)
class StudySettings:
    """What every step reads from the params: the sections it needs and, per run, the
    reference's floor's inputs (its odometry's pose file, its source's times file)."""

    real: RealSection
    trials: TrialsSection
    fixed: FixedSection
    descriptors: Any
    surrogate: Any
    selection: Any
    seed: int
    floors: Mapping[str, tuple[Path, Path]]


def load_settings(params_path: Path) -> StudySettings:
    """The sections of the params file the study reads."""
    from pipeline.config import BaseSection, SelectSection, load_section
    from pipeline.descriptors.dataset import DescriptorsSection
    from pipeline.surrogates.section import SurrogateSection

    real = load_section(params_path, "real", RealSection)
    return StudySettings(real, load_section(params_path, "trials", TrialsSection),
                         load_section(params_path, "fixed", FixedSection),
                         load_section(params_path, "descriptors", DescriptorsSection),
                         load_section(params_path, "surrogate", SurrogateSection),
                         load_section(params_path, "select", SelectSection).settings(),
                         load_section(params_path, "base", BaseSection).seed,
                         floor_inputs(params_path, real))


def floor_inputs(params_path: Path, real: RealSection) -> dict[str, tuple[Path, Path]]:
    """Per run: its odometry's pose file and the times file of the ``data`` source of its
    name (ConfigError for a run without a folder source with a times file)."""
    from pipeline.config import load_section
    from pipeline.errors import ConfigError
    from pipeline.sources.dataset import DataSection
    from pipeline.sources.poses import resolve_path

    base = Path(params_path).resolve().parent
    sources = {s.name: s.resolved(base) for s in load_section(params_path, "data",
                                                              DataSection).sources}
    out = {}
    for run in real.runs:
        times = getattr(sources.get(run.name), "times", None)
        if times is None:
            raise ConfigError(f"real.runs: {run.name!r} is no data source with a times file "
                              f"(sources: {', '.join(map(str, sources))})")
        out[run.name] = (Path(str(resolve_path(run.odometry, base))), Path(times))
    return out


def algorithm_settings(settings: StudySettings, algorithm: str) -> TrialsSection:
    """``trials`` for ``algorithm``: its search space and untuned options from ``real``."""
    from pipeline.config import validate_section

    real = settings.real
    if algorithm not in real.algorithms:
        from pipeline.errors import ConfigError

        raise ConfigError(f"real.algorithms: {algorithm!r} is not one of "
                          f"{', '.join(real.algorithms)}")
    space = {k: v.model_dump(exclude_none=True) for k, v in real.spaces.get(algorithm, {}).items()}
    return validate_section(TrialsSection, "trials", {
        **settings.trials.model_dump(), "algorithm": algorithm, "space": space,
        "adapter_options": dict(real.adapter_options.get(algorithm, {}))})
