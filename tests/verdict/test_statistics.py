"""The verdict's statistics against hand-computed cases (studies/suites/statistics.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from studies.suites.statistics import (
    closed_gap,
    detectable_ratio,
    geometric_mean,
    log_spread,
    median_over_runs,
    pooled,
    ratio_estimate,
    wilson,
    worlds_needed,
)


def test_geometric_mean_by_hand() -> None:
    assert geometric_mean([0.5, 2.0, 1.0]) == pytest.approx(1.0)
    assert geometric_mean([0.25, 1.0]) == pytest.approx(0.5)
    assert geometric_mean([8.0]) == pytest.approx(8.0)
    # a NaN (no score), a zero or a negative ratio is left out, not averaged
    assert geometric_mean([0.25, 1.0, math.nan, 0.0, -1.0]) == pytest.approx(0.5)
    assert math.isnan(geometric_mean([]))


def test_median_over_runs_leaves_failed_runs_out() -> None:
    assert median_over_runs([1.0, 9.0, 2.0]) == 2.0
    assert median_over_runs([1.0, math.nan, 3.0]) == 2.0
    assert math.isnan(median_over_runs([math.nan]))


def test_wilson_by_hand() -> None:
    """8 of 10 at 95 %: centre (k + z^2/2) / (n + z^2), half width
    z / (n + z^2) sqrt(k (n - k) / n + z^2 / 4), z = 1.959964."""
    z = 1.959963984540054
    k, n = 8, 10
    centre = (k + z * z / 2) / (n + z * z)
    half = z / (n + z * z) * math.sqrt(k * (n - k) / n + z * z / 4)
    est = wilson(k, n)
    assert est.value == 0.8
    assert est.low == pytest.approx(centre - half, abs=1e-12)
    assert est.high == pytest.approx(centre + half, abs=1e-12)
    assert (round(est.low, 4), round(est.high, 4)) == (0.4902, 0.9433)
    assert wilson(0, 0).value is None
    assert wilson(0, 5).low == 0.0  # the interval stays inside [0, 1]


def test_ratio_interval_is_in_ratio_units_and_not_symmetric() -> None:
    rng = np.random.default_rng(1)
    ratios = np.exp(rng.normal(np.log(0.7), 0.5, 40))
    est = ratio_estimate(ratios, resamples=2000, seed=3)
    assert est.value == pytest.approx(geometric_mean(ratios))
    assert est.low is not None and est.high is not None
    assert est.low < est.value < est.high
    # symmetric in logs, so not in ratios: the upper arm is the longer one
    assert est.high - est.value > est.value - est.low
    # the same call gives the same interval (seeded), another seed a slightly different one
    assert ratio_estimate(ratios, resamples=2000, seed=3) == est
    assert ratio_estimate(ratios, resamples=2000, seed=4) != est


def test_ratio_interval_degenerate_cases() -> None:
    one = ratio_estimate([0.5])
    assert (one.value, one.low, one.high) == (0.5, None, None)
    same = ratio_estimate([0.5, 0.5, 0.5])
    assert same.value == pytest.approx(0.5)
    assert same.low == pytest.approx(0.5) and same.high == pytest.approx(0.5)
    assert ratio_estimate([]).value is None


def test_ratio_interval_covers_the_true_geometric_mean() -> None:
    """Coverage of the 95 % interval over 200 suites of 30 lognormal worlds: about 93 % (a
    bootstrap interval of 30 worlds covers a little less than it claims; 400 suites gave
    0.93), far from a 68 % or a 99.9 % interval."""
    rng = np.random.default_rng(7)
    truth = 0.8
    covered = 0
    trials = 200
    for i in range(trials):
        ratios = np.exp(rng.normal(np.log(truth), 0.6, 30))
        est = ratio_estimate(ratios, resamples=499, seed=i)
        assert est.low is not None and est.high is not None
        covered += est.low <= truth <= est.high
    assert 0.87 <= covered / trials <= 0.99


def test_closed_gap_by_hand() -> None:
    sbs_over_oracle = np.log([2.0, 1.5, 3.0, 1.2])
    # adaptive as good as SBS: 0; as good as the oracle: 1; half of every log: 0.5
    assert closed_gap(np.zeros(4), sbs_over_oracle).value == pytest.approx(0.0)
    assert closed_gap(sbs_over_oracle, sbs_over_oracle).value == pytest.approx(1.0)
    assert closed_gap(sbs_over_oracle / 2, sbs_over_oracle).value == pytest.approx(0.5)
    # worse than SBS: negative; the gap is a ratio of the suite's mean logs, not a mean of ratios
    gap = closed_gap(np.log([0.5, 1.0, 1.0, 1.0]), np.log([2.0, 2.0, 2.0, 2.0]))
    assert gap.value == pytest.approx(-0.25)
    # no headroom at all: undefined
    assert closed_gap(np.log([0.5, 2.0]), np.zeros(2)).value is None


def test_closed_gap_interval_is_paired() -> None:
    """Adaptive closes exactly 60 % of every world's gap, however large it is: resampled
    worlds keep their pairs, so every resample gives 0.6."""
    rng = np.random.default_rng(2)
    o = rng.uniform(0.1, 1.0, 25)
    gap = closed_gap(0.6 * o, o, resamples=999)
    assert gap.value == pytest.approx(0.6)
    assert gap.low == pytest.approx(0.6) and gap.high == pytest.approx(0.6)
    noisy = closed_gap(0.6 * o + rng.normal(0, 0.1, 25), o, resamples=999, seed=1)
    assert noisy.low is not None and noisy.high is not None
    assert noisy.low < noisy.value < noisy.high  # type: ignore[operator]


def test_pooled_rte_weights_every_sub_trajectory_equally() -> None:
    short = [1.0, 3.0]  # one world with 2 sub-trajectories (and a frame without one)
    long = [2.0, 2.0, 2.0, 30.0, math.nan]
    out = pooled([short, long], threshold_pct=10.0)
    assert out["rte_pct"] == pytest.approx((1 + 3 + 2 + 2 + 2 + 30) / 6)
    assert out["failure_rate"] == pytest.approx(1 / 6)
    assert out["sub_trajectories"] == 6
    assert pooled([], 10.0)["rte_pct"] is None


def test_power_analysis_by_hand() -> None:
    """n = 40, s = 0.5: (t_0.975,39 + t_0.80,39) = 2.0227 + 0.8513 = 2.8740;
    exp(-2.8740 * 0.5 / sqrt(40)) = 0.7967."""
    assert detectable_ratio(0.5, 40) == pytest.approx(math.exp(-2.87397 * 0.5 / math.sqrt(40)),
                                                      rel=1e-4)
    assert detectable_ratio(0.5, 40) == pytest.approx(0.7967, abs=1e-4)
    # more worlds detect smaller effects; a wider spread needs more worlds
    assert detectable_ratio(0.5, 80) > detectable_ratio(0.5, 40)
    n = worlds_needed(0.5, 0.75, bound=0.90)
    assert n is not None
    assert 0.90 * detectable_ratio(0.5, n) >= 0.75
    assert 0.90 * detectable_ratio(0.5, n - 1) < 0.75
    assert worlds_needed(1.0, 0.75, 0.90) > n  # type: ignore[operator]
    assert worlds_needed(0.5, 0.95, bound=0.90) is None
    assert log_spread([1.0, math.e]) == pytest.approx(math.sqrt(0.5))
