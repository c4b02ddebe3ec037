"""The real-data study's folds: which units train and which are tested (docs/results/real.md).

A *unit* is a contiguous stretch of one run that a study runs on: the first or the second half
of a run by distance (``h1``, ``h2``; a run cut into pieces where its keyframes leave a gap gives
a unit per piece and half). Two families of folds, reported apart:

- *in distribution* (``in_a``, ``in_b``): ``in_a`` trains on every run's first half and tests on
  every second half, ``in_b`` the other way round, so every environment and sensor is seen in
  training, on other ground;
- *out of environment* (``out_<run>``): a run of ``out_of_environment`` is left out, the fold
  trains on the other such runs (both halves) and tests on the run left out (both halves).

A test run's ratios pool its units' start frames; over runs the families' figures are
geometric means (``studies.real.summary``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from studies.real.section import RealSection

IN_DISTRIBUTION, OUT_OF_ENVIRONMENT = "in_distribution", "out_of_environment"
FAMILIES = (IN_DISTRIBUTION, OUT_OF_ENVIRONMENT)


@dataclass(frozen=True)
class Unit:
    """A unit: its name (its MCAP's stem), the run and the half it belongs to."""

    name: str
    run: str
    half: str


@dataclass(frozen=True)
class Fold:
    """A fold: its name, family, the units it trains on and, per test run, the units it tests
    on."""

    name: str
    family: str
    train: tuple[str, ...]
    test: Mapping[str, tuple[str, ...]]

    @property
    def test_units(self) -> list[str]:
        return [u for units in self.test.values() for u in units]


def folds(units: Sequence[Unit], section: RealSection) -> list[Fold]:
    """Every fold of the study over ``units`` (module docstring), in-distribution first."""
    def of(runs: Sequence[str], half: str | None = None) -> tuple[str, ...]:
        return tuple(u.name for u in units if u.run in runs and half in (None, u.half))

    runs = [r.name for r in section.runs]
    out = [Fold("in_a", IN_DISTRIBUTION, of(runs, "h1"), {r: of([r], "h2") for r in runs}),
           Fold("in_b", IN_DISTRIBUTION, of(runs, "h2"), {r: of([r], "h1") for r in runs})]
    ooe = [r.name for r in section.runs if r.out_of_environment]
    for left in ooe:
        out.append(Fold(f"out_{left}", OUT_OF_ENVIRONMENT,
                        of([r for r in ooe if r != left]), {left: of([left])}))
    return [f for f in out if f.train and any(f.test.values())]


def fold_named(units: Sequence[Unit], section: RealSection, name: str) -> Fold:
    """The fold ``name`` (ValueError naming the known ones)."""
    known = folds(units, section)
    for f in known:
        if f.name == name:
            return f
    raise ValueError(f"no fold {name!r} (known: {', '.join(f.name for f in known)})")
