"""The moving-block bootstrap of a run's ratio (studies.suites.statistics.block_ratio) against a
case computed by hand: 4 start frames, blocks of 2."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from studies.suites.statistics import block_ratio

NUM = np.array([1.0, 2.0, 4.0, 8.0])
DEN = np.array([2.0, 2.0, 2.0, 2.0])


def by_hand() -> list[float]:
    """Every resample of 4 frames in blocks of 2: the blocks start at frame 0, 1 or 2, two
    blocks a resample, nine resamples, each as likely."""
    blocks = [[0, 1], [1, 2], [2, 3]]
    return [NUM[a + b].mean() / DEN[a + b].mean()
            for a, b in itertools.product(blocks, blocks)]


def test_the_value_is_the_ratio_of_the_means() -> None:
    assert block_ratio(NUM, DEN, 2).value == pytest.approx(15 / 4 / 2)


def test_the_interval_spans_the_resamples_computed_by_hand() -> None:
    """Each of the nine resamples has 1/9 > 2.5 % of the mass: the 95 % interval's ends are the
    smallest and the largest of them, (1 + 2 + 1 + 2) / 4 / 2 = 0.75 and (4 + 8 + 4 + 8) / 4 / 2
    = 3."""
    values = by_hand()
    assert (min(values), max(values)) == (0.75, 3.0)
    est = block_ratio(NUM, DEN, 2, resamples=10000, seed=7)
    assert (est.low, est.high) == (0.75, 3.0)


def test_a_block_of_one_frame_is_the_iid_bootstrap_and_a_block_of_the_run_has_no_spread() -> None:
    iid = block_ratio(NUM, DEN, 1, resamples=10000, seed=7)
    assert iid.low is not None and iid.high is not None
    assert iid.low < 15 / 8 < iid.high
    whole = block_ratio(NUM, DEN, 4, resamples=200, seed=7)
    assert whole.low == whole.high == whole.value  # one block: every resample is the run


def test_no_interval_below_two_frames() -> None:
    one = block_ratio([2.0], [1.0], 5)
    assert (one.value, one.low, one.high) == (2.0, None, None)
