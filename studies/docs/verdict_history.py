"""The history of the runs on the verdict's test suites: every earlier look at them, read from
one committed record (docs/results/verdict-history.yaml) and rendered as a section of
docs/results/verdict.md (``studies.docs.verdict_page``; issue 56, "The history").

The record holds an entry per run and suite: the verdict's runs of both test suites, the
headroom's runs on the id test suite, the experiments and analyses that read its oracle runs or
its metrics, and the runs of the same suites on another machine. Each entry names the commit
that holds its figures and where in that commit they are: a metrics file (``metrics``: its
figures are that file's at ``commit``, which tests/verdict/test_history.py checks against git)
or a commit message or docs page (``quoted``: the figures as printed there)."""

from __future__ import annotations

import datetime
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, model_validator

from pipeline.config import Section, validate_section
from pipeline.errors import ConfigError
from studies.docs.markdown import bullet as _bullet
from studies.docs.markdown import number as _f
from studies.docs.markdown import percent as _pct
from studies.docs.markdown import table as _table

HISTORY = Path("docs/results/verdict-history.yaml")

RATIO_TITLES = {"adaptive_vs_fixed": "adaptive / fixed",
                "adaptive_vs_baseline": "adaptive / baseline",
                "adaptive_vs_best": "adaptive / min(baseline, fixed)",
                "adaptive_vs_sbs": "adaptive / SBS",
                "oracle_vs_sbs": "cross-fitted oracle / SBS",
                "class_oracle_vs_sbs": "class oracle / SBS"}
"""The ratios a suite's or the headroom's metrics give (their ``ratios`` block)."""
GAP_TITLES = {"closed_gap_oracle": "closed gap (cross-fitted oracle)",
              "closed_gap_class_oracle": "closed gap (class oracle)"}
"""The headroom's closed gaps (its ``closed_gap`` block), shares rendered as percentages."""
CONTROL_TITLES = {
    "one_set_vs_sbs": "one set, best on the other worlds / SBS",
    "label_vs_sbs": "per label, best on the other worlds / SBS",
    "label_sensor_vs_sbs": "per label, best on the other worlds of the same sensor / SBS",
    "label_in_sample_vs_sbs": "per label, the world's own best (in sample) / SBS",
    "label_vs_one_set": "per label / one set",
    "label_sensor_vs_label": "per label and sensor / per label"}
"""The choices ``experiments/headroom_controls.py`` compares on the oracles' selection
replica."""
TITLES = {**RATIO_TITLES, **GAP_TITLES, **CONTROL_TITLES}
VERDICT_COLUMNS = ("adaptive_vs_fixed", "adaptive_vs_baseline", "adaptive_vs_best")
"""The figures of a verdict run's row, one column each."""
KIND_TITLES = {"verdict": "the suite's baseline, fixed and adaptive runs (`make verdict`, or its "
                          "suite's stage)",
               "headroom": "the oracles' runs and the closed gap (`make verdict-headroom`), or "
                           "the closed gap scored again on stored oracle runs",
               "experiment": "an experiment on the oracles' stored runs (nothing run on a world)",
               "analysis": "a new reading of committed metrics (nothing run)"}


class Figure(Section):
    """One figure: the value and, where recorded, its 95 % interval."""

    value: float
    low: float | None = None
    high: float | None = None

    @model_validator(mode="after")
    def _both_ends(self) -> Figure:
        if (self.low is None) != (self.high is None):
            raise ValueError(f"an interval needs both ends, got (low={self.low}, "
                             f"high={self.high})")
        return self


def _figure_name(name: str) -> str:
    """``name`` (a key of TITLES, or ``<key>@<sensor>`` for one sensor's worlds) if known."""
    key, _, sensor = name.partition("@")
    if key not in TITLES or (sensor == "" and "@" in name):
        raise ValueError(f"figure {name!r} must be one of {sorted(TITLES)}, optionally "
                         "followed by @<sensor>")
    return name


class Entry(Section):
    """A run (or reading) of one test suite: an item of the record's ``runs``."""

    commit: str = Field(pattern=r"^[0-9a-f]{7,40}$")  # the commit that holds the figures
    date: datetime.date
    code: str = Field(pattern=r"^[0-9a-f]{7,40}( .+)?$")  # the code that ran: its commit,
    # then what the source adds (another commit, the script)
    kind: Literal["verdict", "headroom", "experiment", "analysis"]
    suite: Literal["id", "ood"]
    generator: int = Field(ge=1)  # the world generator (pipeline.sim.GENERATOR_VERSION)
    machine: str
    selector: str | None = None  # the adaptive arm's, if one ran or is quoted
    figures: dict[str, Figure] = Field(min_length=1)
    metrics: str | None = None  # the metrics file at ``commit`` the figures are from
    quoted: str | None = None  # else where in ``commit`` they are printed
    note: str = ""

    @model_validator(mode="after")
    def _one_source(self) -> Entry:
        if (self.metrics is None) == (self.quoted is None):
            raise ValueError(f"{self.commit}: name exactly one source of the figures, metrics "
                             f"or quoted, got (metrics={self.metrics!r}, "
                             f"quoted={self.quoted!r})")
        for name in self.figures:
            _figure_name(name)
        return self


class History(Section):
    """docs/results/verdict-history.yaml: the machines and selectors the entries name, and
    the entries in the order they ran."""

    machines: dict[str, str] = Field(min_length=1)
    selectors: dict[str, str] = Field(min_length=1)
    runs: list[Entry] = Field(min_length=1)

    @model_validator(mode="after")
    def _known_names(self) -> History:
        for e in self.runs:
            if e.machine not in self.machines:
                raise ValueError(f"{e.commit}: machine {e.machine!r} must be one of "
                                 f"{sorted(self.machines)}")
            if e.selector is not None and e.selector not in self.selectors:
                raise ValueError(f"{e.commit}: selector {e.selector!r} must be one of "
                                 f"{sorted(self.selectors)}")
        return self


def metrics_figure(metrics: Mapping[str, Any], name: str) -> Figure:
    """The figure ``name`` (a key of RATIO_TITLES or GAP_TITLES) of a suite's or the headroom's
    metrics, as an entry whose source is that file records it."""
    if name in GAP_TITLES:
        g = metrics["closed_gap"][name.removeprefix("closed_gap_")]
        return Figure(value=g["value"], low=g["low"], high=g["high"])
    s = metrics["ratios"][name]
    return Figure(value=s["geomean"], low=s["low"], high=s["high"])


def _figure(name: str, f: Figure) -> str:
    """``f`` as the rest of the page prints its kind: a ratio to two decimals with its interval
    ``(low-high)``, a closed gap as whole percentages ``(low to high)``."""
    if name.partition("@")[0] in GAP_TITLES:
        value = _pct(f.value)
        interval = f" ({_pct(f.low)} to {_pct(f.high)})"
    else:
        value = _f(f.value, 2)
        interval = f" ({_f(f.low, 2)}-{_f(f.high, 2)})"
    return value + (interval if f.low is not None else "")


def _title(name: str) -> str:
    key, _, sensor = name.partition("@")
    return TITLES[key] + (f" ({sensor})" if sensor else "")


def _source(e: Entry) -> str:
    return f"`{e.metrics}` at {e.commit}" if e.metrics else f"{e.quoted} ({e.commit})"


def history_section(history: History, source: str = HISTORY.as_posix()) -> list[str]:
    """The page's section: the verdict's runs (one row per run and suite, a column per ratio),
    then the headroom, experiments and readings (their figures in one cell), the machines and
    selectors named, and every entry's note; ``source``: the record's path, quoted."""
    runs = [e for e in history.runs if e.kind == "verdict"]
    others = [e for e in history.runs if e.kind != "verdict"]
    run_rows = [[e.commit, e.date, e.code, e.machine, e.generator, e.selector or "-", e.suite,
                 *(_figure(n, e.figures[n]) if n in e.figures else "-"
                   for n in VERDICT_COLUMNS), _source(e)] for e in runs]
    other_rows = [[e.commit, e.date, e.code, e.machine, e.generator, e.kind, e.selector or "-",
                   "; ".join(f"{_title(n)} {_figure(n, f)}" for n, f in e.figures.items()),
                   _source(e)] for e in others]
    notes = [_bullet(f"{e.commit} ({e.kind}, {e.suite}): {e.note}")
             for e in history.runs if e.note]
    return ["## History of the runs on the test suites", "",
            f"Every earlier run on the test suites, in the order they ran, from {source} (one "
            "entry per run and suite; each names the commit that holds its figures and where "
            "in it: a metrics file, checked against git by tests/verdict/test_history.py, or "
            "the commit message or docs page that printed them). Geometric means of the "
            "per-world ratios with their 95 % intervals where recorded. The dev suites' and "
            "the tuning suite's figures are not here: [selector-dev.md](selector-dev.md).", "",
            "The verdict's runs (`make verdict`, or its suites' stages):", "",
            *_table(["commit", "date", "code run", "machine", "generator", "selector", "suite",
                     *(RATIO_TITLES[n] for n in VERDICT_COLUMNS), "figures from"], run_rows),
            "", "The headroom on the id test suite, and what read its oracle runs or metrics:",
            "", *_table(["commit", "date", "code run", "machine", "generator", "what",
                         "selector", "figures", "figures from"], other_rows), "",
            *_legend("Machines", history.machines), *_legend("Selectors", history.selectors),
            *_legend("What", {k: v for k, v in KIND_TITLES.items()
                              if any(e.kind == k for e in history.runs)}),
            *(["Notes:", "", *notes] if notes else [])]


def _legend(title: str, names: Mapping[str, str]) -> list[str]:
    return [f"{title}:", "", *(_bullet(f"{name}: {text}") for name, text in names.items()), ""]


def read_history(data: Any, where: str = HISTORY.as_posix()) -> History:
    """The record ``data`` (parsed YAML) validated; ConfigError naming the value and rule."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: must be a mapping of machines, selectors and runs, got "
                          f"{type(data).__name__}")
    return validate_section(History, where, data)
