"""experiments/verdict_arms.py, run as a user runs it: two suites' metrics files in, the table
of the gate and the paired ratios out (and as JSON with --json); bad input ends in one line on
stderr and exit code 1."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers.verdict_data import suite_metrics, world_medians

from studies.verdict.arms import compare_arms

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "verdict_arms.py"


def _run(*args: Path | str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True,
                          text=True, check=False)


def test_two_arms_give_the_gate_and_the_paired_ratios(tmp_path: Path) -> None:
    medians = world_medians(np.ones(8))
    worse = {w: {**m, "adaptive": 2.0 * m["adaptive"]} for w, m in medians.items()}
    ref, cand, out = tmp_path / "ref.json", tmp_path / "cand.json", tmp_path / "arms.json"
    ref.write_text(json.dumps(suite_metrics(medians)))
    cand.write_text(json.dumps(suite_metrics(worse)))
    done = _run(ref, cand, "--json", out)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "id dev suite, 8 worlds"
    # every adaptive run twice as bad: worse beyond the reference's interval on every ratio
    rows = [row for row in lines if row.startswith("| adaptive_vs_")]
    assert len(rows) == 3 and all(row.endswith("| yes |") for row in rows)
    assert "| adaptive | 2.00 (" in done.stdout and "| fixed | 1.00 (" in done.stdout
    written = json.loads(out.read_text())
    assert written == json.loads(json.dumps(compare_arms(suite_metrics(medians),
                                                         suite_metrics(worse))))


@pytest.mark.parametrize("case", ["other suite", "not json", "missing"])
def test_the_script_ends_bad_input_in_one_line(tmp_path: Path, case: str) -> None:
    medians = world_medians(np.ones(6))
    ref, cand = tmp_path / "ref.json", tmp_path / "cand.json"
    ref.write_text(json.dumps(suite_metrics(medians)))
    if case == "other suite":
        cand.write_text(json.dumps(suite_metrics(medians, suite="test")))
    elif case == "not json":
        cand.write_text("{not json")
    done = _run(ref, cand)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("verdict_arms: error: ")
    assert {"other suite": "same suite", "not json": "Expecting", "missing": "cand.json"}[case] \
        in lines[0]
