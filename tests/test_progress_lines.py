"""Progress of long loops (issue 34, item 7): a bar on a terminal, log lines on the
``pipeline.progress`` logger elsewhere, for ingest, run (tests/odometry/test_odometry_run_cli.py)
and simulate."""

from __future__ import annotations

import io
import logging
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from pipeline.progress import progress
from stages.cli import main


def test_log_lines_every_tenth_off_a_terminal(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "pipeline.progress")
    assert list(progress(range(25), 25, "ingest x", "scan", terminal=False,
                         min_interval_s=0)) == list(range(25))
    lines = [r.getMessage() for r in caplog.records if r.name == "pipeline.progress"]
    assert lines[0] == "ingest x: 25 scans"
    assert [ln.split(" scans")[0] for ln in lines[1:-1]] == [
        f"ingest x: {k}/25" for k in range(3, 25, 3)]
    assert "ETA" in lines[1] and lines[-1].startswith("ingest x finished: 25 scans in ")
    caplog.clear()
    assert list(progress(iter(range(3)), None, "y", terminal=False)) == [0, 1, 2]
    assert [r.getMessage().split(" in ")[0] for r in caplog.records] == [
        "y: ? frames", "y finished: 3 frames"]  # a quick loop: no line between


def test_a_bar_on_a_terminal_and_nothing_when_disabled(monkeypatch: pytest.MonkeyPatch,
                                                       caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "pipeline.progress")
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    assert list(progress(range(5), 5, "run", terminal=True)) == list(range(5))
    assert "run:   0%" in err.getvalue() and "0/5" in err.getvalue() and not caplog.records
    assert list(progress(range(5), 5, "quiet", enabled=False, terminal=False)) == list(range(5))
    assert not caplog.records


def test_simulate_shows_progress(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    result = CliRunner().invoke(main, ["simulate", "--world", "open", "--frames", "10",
                                       "--out", str(tmp_path / "o.mcap")])
    assert result.exit_code == 0, result.output
    assert "simulate o: 10 scans" in caplog.text and "simulate o finished" in caplog.text
