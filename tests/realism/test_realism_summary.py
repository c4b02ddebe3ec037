"""The comparison's figures (docs/design.md, "The sim-to-real comparison"): the median of a
slice's steps (the simulated side over every replica's steps), the 90th percentile of every
slice's steps pooled, simulated / real and the x1.5 target; the slices it accepts."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.sim.kitti_dataset import SimulateKittiSection
from studies.realism.compare import (
    RealismResult,
    SideErrors,
    SliceResult,
    parse_slice,
    run_realism,
)
from studies.realism.statistics import ScanStatistics

STATS = ScanStatistics(1.0, (1.0,), (1.0,), 0.0, 1, 1.0)


def side(t_cm: list[float], r_deg: list[float], replicas: int = 1) -> SideErrors:
    """Step errors of ``replicas`` runs, the steps split evenly between them."""
    t, r = np.array_split(np.array(t_cm), replicas), np.array_split(np.array(r_deg), replicas)
    return SideErrors(t_cm, r_deg, [float(np.median(x)) for x in t],
                      [float(np.median(x)) for x in r])


def two_slices() -> RealismResult:
    """Slice A: real t 1..9 cm, simulated t over 2 replicas 2..19 (even); slice B: real t
    11..19, simulated 10x slice A's real; rotations a tenth of the translations."""
    a_real = [float(v) for v in range(1, 10)]
    a_sim = [float(v) for v in range(2, 20, 2)] + [float(v) for v in range(1, 10)]
    b_real = [float(v) for v in range(11, 20)]
    b_sim = [10.0 * v for v in a_real]
    slices = []
    for name, real, sim in (("A", a_real, a_sim), ("B", b_real, b_sim)):
        simulated = {"gicp": side(sim, [v / 10 for v in sim], replicas=2)}
        slices.append(SliceResult(
            name, 0, 9, "rural", STATS, STATS,
            {"gicp": side(real, [v / 10 for v in real])}, simulated, simulated, None,
            (0.0, 0.0)))
    return RealismResult(slices, ("gicp",), 2, "hdl64", 64, {})


def test_a_slice_is_the_median_of_its_steps_the_simulated_side_over_every_replica() -> None:
    result = two_slices()
    a, b = result.slices
    assert a.real["gicp"].median_t_cm == 5.0
    # the 18 simulated steps of A: 2, 4, .., 18 and 1..9; sorted, the middle pair is 6 and 7
    assert a.sim["gicp"].median_t_cm == 6.5
    assert a.sim["gicp"].replica_t_cm == [10.0, 5.0]
    assert b.real["gicp"].median_r_deg == pytest.approx(1.5)


def test_the_90th_percentile_pools_every_slices_steps() -> None:
    """Real steps pooled: 1..9 and 11..19 (18 values); the 90th percentile at rank
    0.9 x 17 = 15.3 lies between 17 and 18: 17.3. (Per slice it would be 8.2 and 18.2.)"""
    result = two_slices()
    assert result.pooled_p90("gicp", "real", "t_cm") == pytest.approx(17.3)
    assert result.pooled_p90("gicp", "real", "r_deg") == pytest.approx(1.73)
    # simulated: 2..18 even, 1..9, 10..90 by 10 (27 steps); rank 0.9 x 26 = 23.4 lies
    # between 60 and 70
    assert result.pooled_p90("gicp", "sim", "t_cm") == pytest.approx(64.0)


def test_ratios_are_simulated_over_real_and_the_target_is_x1_5_either_way() -> None:
    ratios = two_slices().ratios()
    assert ratios["gicp A median t"] == pytest.approx(6.5 / 5.0)
    assert ratios["gicp B median t"] == pytest.approx(50.0 / 15.0)
    assert ratios["gicp pooled p90 t"] == pytest.approx(64.0 / 17.3)
    within = two_slices().within_target()
    assert within["gicp A median t"] and within["gicp A median r"]  # 1.3
    assert not within["gicp B median t"] and not within["gicp pooled p90 t"]
    assert len(within) == 6


@pytest.mark.parametrize(("text", "message"), [
    ("04", "a slice is NN:FIRST:LAST, e.g. 04:0:9, got '04'"),
    ("04:a:9", "a slice is NN:FIRST:LAST, e.g. 04:0:9, got '04:a:9'"),
    ("04:5:5", "with 0 <= FIRST < LAST, got '04:5:5'"),
    ("04:0:9:1", "with 0 <= FIRST < LAST, got '04:0:9:1'"),
    ("../04:0:9", "must be a plain file name"),
])
def test_a_bad_slice_is_refused_naming_it_and_the_rule(text: str, message: str) -> None:
    assert parse_slice("04:0:9") == ("04", 0, 9)
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_slice(text)


def test_an_unknown_sequence_or_no_replica_is_refused_before_anything_runs() -> None:
    section = SimulateKittiSection()
    with pytest.raises(ConfigError, match="no environment schedule for KITTI sequence '12'"):
        run_realism("/nonexistent", "/nonexistent", section, 1, (("12", 0, 3),))
    with pytest.raises(ConfigError, match="replicas must be >= 1, got 0"):
        run_realism("/nonexistent", "/nonexistent", section, 0)


def test_too_easy_misses_the_target_as_too_hard_does() -> None:
    """Simulated steps half the real ones (0.5 < 1 / 1.5) miss the target as 1.6x does."""
    real = [1.0, 2.0, 3.0]
    for factor, ok in ((0.5, False), (0.7, True), (1.45, True), (1.6, False)):
        simulated = {"gicp": side([factor * v for v in real], [factor * v for v in real])}
        result = RealismResult([SliceResult(
            "A", 0, 3, "rural", STATS, STATS, {"gicp": side(real, real)}, simulated, simulated,
            None, (0.0, 0.0))], ("gicp",), 1, "hdl64", 64, {})
        assert set(result.within_target().values()) == {ok}, factor


def test_the_target_compares_the_side_with_the_ground_truths_error() -> None:
    """Real 1, 2, 3 cm; simulated against the exact ground truth 0.5x (too easy), with the
    ground-truth error added 1x: the target reads the latter, ``ratios("sim")`` the former."""
    real = [1.0, 2.0, 3.0]
    exact = {"gicp": side([0.5 * v for v in real], [0.5 * v for v in real])}
    with_gt = {"gicp": side(real, real)}
    result = RealismResult([SliceResult("A", 0, 3, "rural", STATS, STATS,
                                        {"gicp": side(real, real)}, exact, with_gt, None,
                                        (0.0, 0.0))], ("gicp",), 1, "hdl64", 64, {})
    assert result.ratios()["gicp A median t"] == pytest.approx(1.0)
    assert result.ratios("sim")["gicp A median t"] == pytest.approx(0.5)
    assert all(result.within_target().values())
    assert not any(result.within_target("sim").values())


@pytest.mark.parametrize(("n", "low", "high", "coverage"), [
    # [x(j), x(n + 1 - j)] covers the median with P(j <= B <= n - j), B ~ Binomial(n, 1/2):
    (9, 2.0, 8.0, 1 - 2 * 10 / 512),     # j = 2: 1 - 2 P(B <= 1); j = 3 gives 1 - 2 * 46 / 512
    (5, 1.0, 5.0, 1 - 2 / 32),           # even the extremes cover 93.75 % only
    (20, 6.0, 15.0, 1 - 2 * 21700 / 2**20),  # P(B <= 5) = (1 + 20 + 190 + 1140 + 4845
                                             # + 15504) / 2**20
    (1, 1.0, 1.0, 0.0),
])
def test_the_real_medians_interval_is_of_order_statistics(n: int, low: float, high: float,
                                                          coverage: float) -> None:
    from studies.realism.compare import median_interval

    values = [float(v) for v in np.random.default_rng(n).permutation(np.arange(1, n + 1))]
    got = median_interval(values)
    assert got[:2] == (low, high)
    assert got[2] == pytest.approx(coverage)


def test_a_miss_is_beyond_the_real_sides_noise_only_outside_x1_5_at_both_ends() -> None:
    """Real steps 1..9 cm (median 5, interval 2-8). Simulated median 10 (2x): the range
    10/8 .. 10/2 = 1.25-5 reaches inside x1.5, so the miss may be the real side's few steps;
    simulated median 13: 1.625-6.5, all of it outside, beyond the noise."""
    real = [float(v) for v in range(1, 10)]
    for sim_median, beyond in ((10.0, False), (13.0, True)):
        sim = {"gicp": side([sim_median] * 3, [sim_median] * 3)}
        result = RealismResult([SliceResult("A", 0, 9, "rural", STATS, STATS,
                                            {"gicp": side(real, real)}, sim, sim, None,
                                            (0.0, 0.0))], ("gicp",), 1, "hdl64", 64, {})
        assert not result.within_target()["gicp A median t"]
        low, high = result.ratio_ranges()["gicp A median t"]
        assert (low, high) == pytest.approx((sim_median / 8.0, sim_median / 2.0))
        assert result.beyond_real_noise()["gicp A median t"] is beyond
