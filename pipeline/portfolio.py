"""The portfolio study: a few parameter sets, each run on every training sequence
(docs/design.md, "The portfolio selector").

The per-sequence SMBO studies measure each parameter set on one sequence only, so the
surrogate's mean over a frame's neighbours compares sets measured on different sequences, and
its argmin over thousands of candidates picks the luckiest. The portfolio study measures every
member on every training sequence instead (ISAC-style per-environment tuning, Kadioglu et al.
2010; algorithm selection over a portfolio, as ASlib scores it), so the ``portfolio`` surrogate
rows (``surrogate.rows: portfolio``) hold every member at every training frame and the
selector chooses among the members only.

The members: the baseline (trial 0, the space's defaults), the product of ``portfolio.grid``
(each parameter it does not name at its default), and with ``portfolio.fixed`` the joint
study's best set; sets equal to an earlier one are dropped. Each sequence is one study of
``pipeline.tuning.smbo`` whose trials are exactly the members (``warm_start``), run whole
(no pruning, no halving): its trials folder has the layout of the ``trials`` stage's, so the
``rte`` stage scores it as the study ``portfolio``.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path

from pydantic import Field

from pipeline.config import Section, validate_section
from pipeline.errors import ConfigError
from pipeline.odometry.base import ParameterSpace, Params, grid_sets
from pipeline.tuning.section import TrialsSection
from pipeline.tuning.smbo import StudySummary, run_trials, study_adapter

log = logging.getLogger(__name__)


class PortfolioSection(Section):
    """params.yaml ``portfolio``: the members of the portfolio study (module docstring).

    grid: parameter name -> its values; the members are their product, every other parameter
    at its default ({}: no grid). fixed: add the joint study's best parameters.
    """

    grid: dict[str, list[float]] = Field(default_factory=dict)
    fixed: bool = True


def portfolio_members(space: ParameterSpace, section: PortfolioSection,
                      fixed: Mapping[str, float] | None) -> list[Params]:
    """The members after the baseline, in order: the grid's product (``grid_sets``), then
    ``fixed`` when ``section.fixed``; without sets equal to the baseline or to an earlier
    member. ConfigError naming a parameter the space does not have, an empty value list or a
    value out of range."""
    unknown = [n for n in section.grid if n not in space.names]
    if unknown:
        raise ConfigError(f"portfolio.grid: unknown parameter {unknown[0]!r} (known: "
                          f"{', '.join(space.names)})")
    empty = [n for n, values in section.grid.items() if not values]
    if empty:
        raise ConfigError(f"portfolio.grid.{empty[0]} must list at least one value, got []")
    try:
        members = space.distinct(grid_sets(section.grid))
    except ConfigError as exc:  # a grid value out of range: name the setting
        raise ConfigError(f"portfolio.grid: {exc}") from None
    if section.fixed:
        if fixed is None:
            raise ConfigError("portfolio.fixed needs the joint study's output (--fixed DIR)")
        members.append(dict(fixed))
    return space.distinct([space.defaults(), *members])[1:]


def run_portfolio(sequence_paths: Sequence[str | Path], out_dir: str | Path,
                  settings: TrialsSection, section: PortfolioSection, seed: int,
                  fixed: Mapping[str, float] | None = None) -> list[StudySummary]:
    """Run every member on every sequence of ``sequence_paths`` into ``out_dir`` (resumable as
    the trials stage is): one study per sequence, trial 0 the baseline, trial i member i."""
    members = portfolio_members(study_adapter(settings).space, section, fixed)
    whole = validate_section(TrialsSection, "trials", {
        **settings.model_dump(), "iterations": 1 + len(members), "fidelity": "whole",
        "pruning": {**settings.pruning.model_dump(), "percentile": None}})
    log.info("portfolio: %d members and the baseline on %d sequences", len(members),
             len(sequence_paths))
    return run_trials(sequence_paths, out_dir, whole, seed, warm_start=members)
