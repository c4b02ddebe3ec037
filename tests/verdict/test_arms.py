"""Two arms of one suite (studies.verdict.arms): the gate "not worse beyond the reference's
interval" and the paired per-setting ratios, on hand-made suite metrics."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.errors import InputError
from studies.verdict.arms import compare_arms
from studies.verdict.summary import RATIOS, ratio_summary

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "verdict_arms.py"


def _suite(medians: dict[str, dict[str, float]], suite: str = "dev") -> dict[str, Any]:
    """A suite's metrics as studies.verdict.summary writes them, from per-world medians."""
    def ratio(w: dict[str, float], den: str) -> float:
        d = min(w["baseline"], w["fixed"]) if den == "min" else w[den]
        return w["adaptive"] / d

    per_world = {name: {"median_rte_pct": m,
                        "ratios": {r: ratio(m, den) for r, (den,) in RATIOS.items()}}
                 for name, m in medians.items()}
    ratios = {r: ratio_summary([w["ratios"][r] for w in per_world.values()], 0.95, 999, 0)
              for r in RATIOS}
    return {"family": "id", "suite": suite, "seed_root": 70101, "per_world": per_world,
            "ratios": ratios}


def _medians(adaptive_scale: np.ndarray) -> dict[str, dict[str, float]]:
    rng = np.random.default_rng(3)
    out = {}
    for i, scale in enumerate(adaptive_scale):
        b, f = rng.uniform(2.0, 6.0, 2)
        out[f"w{i:02d}"] = {"baseline": float(b), "fixed": float(f),
                            "adaptive": float(0.6 * f * scale * rng.uniform(0.8, 1.2))}
    return out


def test_the_same_run_is_not_worse_and_pairs_to_one() -> None:
    ref = _suite(_medians(np.ones(12)))
    result = compare_arms(ref, ref)
    assert result["worlds"] == 12
    assert not result["worse_beyond_intervals"]
    for e in result["paired"].values():
        assert e["value"] == pytest.approx(1.0)


def test_a_candidate_twice_as_bad_is_worse_beyond_the_interval() -> None:
    medians = _medians(np.ones(12))
    worse = {w: {**m, "adaptive": 2.0 * m["adaptive"]} for w, m in medians.items()}
    result = compare_arms(_suite(medians), _suite(worse))
    assert result["worse_beyond_intervals"]
    assert result["ratios"]["adaptive_vs_fixed"]["worse_beyond_interval"]
    # by hand: every world's adaptive doubled, the others unchanged
    assert result["paired"]["adaptive"]["value"] == pytest.approx(2.0)
    assert result["paired"]["fixed"]["value"] == pytest.approx(1.0)


def test_a_small_change_inside_the_interval_passes() -> None:
    medians = _medians(np.ones(12))
    ref = _suite(medians)
    slightly = {w: {**m, "adaptive": 1.02 * m["adaptive"]} for w, m in medians.items()}
    result = compare_arms(ref, _suite(slightly))
    assert not result["worse_beyond_intervals"]
    high = ref["ratios"]["adaptive_vs_fixed"]["high"]
    assert result["ratios"]["adaptive_vs_fixed"]["candidate"]["geomean"] < high


def test_arms_of_other_suites_or_worlds_are_refused() -> None:
    medians = _medians(np.ones(6))
    with pytest.raises(InputError, match="suite='dev' against 'test'"):
        compare_arms(_suite(medians), _suite(medians, suite="test"))
    fewer = dict(list(medians.items())[:5])
    with pytest.raises(InputError, match="same worlds"):
        compare_arms(_suite(medians), _suite(fewer))


def test_a_file_that_is_not_a_suite_is_refused() -> None:
    medians = _medians(np.ones(6))
    with pytest.raises(InputError, match=r"candidate is not a suite's metrics.*'per_world'"):
        compare_arms(_suite(medians), {"family": "id", "suite": "dev", "seed_root": 70101})


@pytest.mark.parametrize("case", ["other suite", "not json", "missing"])
def test_the_script_ends_bad_input_in_one_line(tmp_path: Path, case: str) -> None:
    """experiments/verdict_arms.py: one line on stderr naming the problem, exit code 1."""
    medians = _medians(np.ones(6))
    ref, cand = tmp_path / "ref.json", tmp_path / "cand.json"
    ref.write_text(json.dumps(_suite(medians)))
    if case == "other suite":
        cand.write_text(json.dumps(_suite(medians, suite="test")))
    elif case == "not json":
        cand.write_text("{not json")
    out = subprocess.run([sys.executable, str(SCRIPT), str(ref), str(cand)],
                         capture_output=True, text=True, check=False)
    assert out.returncode == 1
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("verdict_arms: error: ")
    assert {"other suite": "same suite", "not json": "Expecting", "missing": "cand.json"}[case] \
        in lines[0]
