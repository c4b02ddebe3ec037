"""The history of the runs on the verdict's test suites (studies/docs/verdict_history.py, issue
56): the record validates, its commits exist, every figure it takes from a metrics file is that
file's at its commit, and docs/results/verdict.md renders it as two tables."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.errors import ConfigError
from studies.docs.verdict_history import (
    HISTORY,
    History,
    history_section,
    metrics_figure,
    read_history,
)
from studies.docs.verdict_page import ID, verdict_page

REPO = Path(__file__).resolve().parents[2]


def _entry(**fields: Any) -> dict[str, Any]:
    base = {"commit": "abc1234", "date": "2026-11-25", "code": "abc1234", "kind": "verdict",
            "suite": "id", "generator": 2, "machine": "one", "selector": "paper",
            "metrics": "verdict/metrics/id.json",
            "figures": {"adaptive_vs_fixed": {"value": 0.8706, "low": 0.6814, "high": 1.2086}}}
    return {**base, **fields}


def _record(*runs: dict[str, Any]) -> dict[str, Any]:
    return {"machines": {"one": "the first", "two": "the second"},
            "selectors": {"paper": "the paper's", "portfolio": "one model per sensor"},
            "runs": list(runs)}


HAND_MADE = _record(
    _entry(note="the first run"),
    _entry(commit="def5678", date="2026-11-27", code="fed8765", suite="ood", machine="two",
           selector="portfolio", metrics=None, quoted="verdict-protocol.md, \"A second run\"",
           figures={"adaptive_vs_fixed": {"value": 0.76, "low": 0.59, "high": 0.92},
                    "adaptive_vs_baseline": {"value": 0.92, "low": 0.84, "high": 1.03}}),
    _entry(commit="1234abc", kind="headroom", metrics="verdict/metrics/headroom.json",
           figures={"oracle_vs_sbs": {"value": 0.79, "low": 0.64, "high": 0.95},
                    "closed_gap_oracle": {"value": -0.066, "low": -3.4, "high": 0.418}}),
    _entry(commit="5678def", kind="analysis", metrics=None, quoted="the commit message",
           figures={"adaptive_vs_fixed@hdl32": {"value": 0.59},
                    "adaptive_vs_fixed@hdl64": {"value": 0.995}}))


def test_the_history_renders_a_row_per_run_and_suite() -> None:
    """The verdict's runs a column per ratio ('-' where the source gives none), the others their
    figures in one cell (a closed gap in percent, a sensor's figure named by its sensor), each
    with where its figures are; the notes, machines and selectors listed."""
    lines = history_section(read_history(HAND_MADE))
    assert lines[0] == "## History of the runs on the test suites"
    rows = [line for line in lines if re.match(r"\| [0-9a-f]{7} \|", line)]
    assert rows == [
        "| abc1234 | 2026-11-25 | abc1234 | one | 2 | paper | id | 0.87 (0.68-1.21) | - | - "
        "| `verdict/metrics/id.json` at abc1234 |",
        "| def5678 | 2026-11-27 | fed8765 | two | 2 | portfolio | ood | 0.76 (0.59-0.92) "
        "| 0.92 (0.84-1.03) | - | verdict-protocol.md, \"A second run\" (def5678) |",
        "| 1234abc | 2026-11-25 | abc1234 | one | 2 | headroom | paper | cross-fitted oracle / "
        "SBS 0.79 (0.64-0.95); closed gap (cross-fitted oracle) -7 % (-340 % to 42 %) "
        "| `verdict/metrics/headroom.json` at 1234abc |",
        "| 5678def | 2026-11-25 | abc1234 | one | 2 | analysis | paper | adaptive / fixed "
        "(hdl32) 0.59; adaptive / fixed (hdl64) 0.99 | the commit message (5678def) |"]
    assert "- abc1234 (verdict, id): the first run" in lines
    assert "- two: the second" in lines and "- portfolio: one model per sensor" in lines


def test_the_page_carries_the_history_before_its_worlds() -> None:
    from test_page import suite

    ids, _ = suite("id", 0.6, 4)
    page = verdict_page({ID: ids}, ["> provenance"], {}, read_history(HAND_MADE))
    assert page.index("## History of the runs") < page.index("<details><summary>Every world")
    assert "| def5678 | 2026-11-27 |" in page
    assert "History" not in verdict_page({ID: ids}, ["> provenance"], {})


@pytest.mark.parametrize(("change", "rule"), [
    ({"machine": "three"}, r"machine 'three' must be one of \['one', 'two'\]"),
    ({"selector": "oracle"}, r"selector 'oracle' must be one of"),
    ({"quoted": "the commit message"}, r"exactly one source of the figures"),
    ({"metrics": None}, r"exactly one source of the figures"),
    ({"figures": {"adaptive_vs_oracle": {"value": 1.0}}}, r"figure 'adaptive_vs_oracle' must"),
    ({"figures": {"adaptive_vs_fixed@": {"value": 1.0}}}, r"figure 'adaptive_vs_fixed@' must"),
    ({"figures": {"adaptive_vs_fixed": {"value": 1.0, "low": 0.9}}}, r"needs both ends"),
    ({"figures": {}}, r"figures"),
    ({"commit": "HEAD"}, r"commit"),
    ({"code": "the branch verdict2"}, r"code"),
    ({"suite": "dev"}, r"suite"),
    ({"kind": "guess"}, r"kind"),
])
def test_a_bad_entry_is_refused_naming_the_rule(change: dict[str, Any], rule: str) -> None:
    with pytest.raises(ConfigError, match=rule):
        read_history(_record(_entry(**change)))


def test_a_record_that_is_no_mapping_is_refused() -> None:
    with pytest.raises(ConfigError, match="must be a mapping"):
        read_history([_entry()])


# ---------------------------------------------------------------- the committed record


def _committed() -> History:
    return read_history(yaml.safe_load((REPO / HISTORY).read_text()))


def _git(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, timeout=60)


@pytest.fixture(scope="module")
def history_git() -> None:
    """The repository's git history (the record's commits are in it); skip in a copy of the
    tree without one, or in a shallow clone."""
    if _git("rev-parse", "--git-dir").returncode != 0:
        pytest.skip("not a git checkout: the record's commits cannot be looked up")
    if _git("rev-parse", "--is-shallow-repository").stdout.strip() == "true":
        pytest.skip("a shallow clone: the record's older commits are not in it "
                    "(git fetch --unshallow)")


def test_the_committed_record_validates_and_covers_both_suites() -> None:
    history = _committed()
    kinds = {(e.kind, e.suite) for e in history.runs}
    assert {("verdict", "id"), ("verdict", "ood"), ("headroom", "id")} <= kinds
    assert [e.date for e in history.runs] == sorted(e.date for e in history.runs)


def test_every_commit_the_record_names_exists(history_git: None) -> None:
    """The commit of every entry and every commit its code names."""
    history = _committed()
    named = {e.commit for e in history.runs} | {
        c for e in history.runs for c in re.findall(r"\b[0-9a-f]{7,40}\b", e.code)}
    missing = [c for c in sorted(named) if _git("cat-file", "-e", f"{c}^{{commit}}").returncode]
    assert missing == []


def test_every_figure_from_a_metrics_file_is_that_files_at_its_commit(
        history_git: None) -> None:
    """`git show COMMIT:FILE` gives each such figure, value and interval, to the last digit."""
    checked = 0
    for e in _committed().runs:
        if e.metrics is None:
            continue
        shown = _git("show", f"{e.commit}:{e.metrics}")
        assert shown.returncode == 0, (e.commit, e.metrics, shown.stderr)
        metrics = json.loads(shown.stdout)
        assert metrics["suite"] == "test" and metrics["family"] == e.suite, e.commit
        assert metrics["world_generator"] == e.generator, e.commit
        for name, figure in e.figures.items():
            assert metrics_figure(metrics, name) == figure, (e.commit, e.metrics, name)
            checked += 1
    assert checked >= 30
