"""Two arms of one suite (studies.verdict.arms): the gate "not worse beyond the reference's
interval" and the paired per-setting ratios, on hand-made suite metrics."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.verdict_data import suite_metrics, world_medians

from pipeline.errors import InputError
from studies.verdict.arms import compare_arms


def test_the_same_run_is_not_worse_and_pairs_to_one() -> None:
    ref = suite_metrics(world_medians(np.ones(12)))
    result = compare_arms(ref, ref)
    assert result["worlds"] == 12
    assert not result["worse_beyond_intervals"]
    for e in result["paired"].values():
        assert e["value"] == pytest.approx(1.0)


def test_a_candidate_twice_as_bad_is_worse_beyond_the_interval() -> None:
    medians = world_medians(np.ones(12))
    worse = {w: {**m, "adaptive": 2.0 * m["adaptive"]} for w, m in medians.items()}
    result = compare_arms(suite_metrics(medians), suite_metrics(worse))
    assert result["worse_beyond_intervals"]
    assert result["ratios"]["adaptive_vs_fixed"]["worse_beyond_interval"]
    # by hand: every world's adaptive doubled, the others unchanged
    assert result["paired"]["adaptive"]["value"] == pytest.approx(2.0)
    assert result["paired"]["fixed"]["value"] == pytest.approx(1.0)


def test_a_small_change_inside_the_interval_passes() -> None:
    medians = world_medians(np.ones(12))
    ref = suite_metrics(medians)
    slightly = {w: {**m, "adaptive": 1.02 * m["adaptive"]} for w, m in medians.items()}
    result = compare_arms(ref, suite_metrics(slightly))
    assert not result["worse_beyond_intervals"]
    high = ref["ratios"]["adaptive_vs_fixed"]["high"]
    assert result["ratios"]["adaptive_vs_fixed"]["candidate"]["geomean"] < high


def test_arms_of_other_suites_or_worlds_are_refused() -> None:
    medians = world_medians(np.ones(6))
    with pytest.raises(InputError, match="suite='dev' against 'test'"):
        compare_arms(suite_metrics(medians), suite_metrics(medians, suite="test"))
    fewer = dict(list(medians.items())[:5])
    with pytest.raises(InputError, match="same worlds"):
        compare_arms(suite_metrics(medians), suite_metrics(fewer))


def test_a_file_that_is_not_a_suite_is_refused() -> None:
    medians = world_medians(np.ones(6))
    with pytest.raises(InputError, match=r"candidate is not a suite's metrics.*'per_world'"):
        compare_arms(suite_metrics(medians), {"family": "id", "suite": "dev", "seed_root": 70101})
