"""The KITTI protocol's cost model (bench/bench_kitti.py; docs/kitti.md, "What the full protocol
costs"), on cases computed by hand: one frame costs 1 s with sampled parameters and 0.5 s with
the defaults, and the path advances 1 m a frame."""

from __future__ import annotations

import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from helpers.scripts import load_script

from pipeline.tuning.pruning import HalvingSection

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture(scope="module")
def model() -> ModuleType:
    """bench/bench_kitti.py as a module (bench/ on the path for its ``common``)."""
    sys.path.insert(0, str(BENCH))
    try:
        return load_script(BENCH / "bench_kitti.py")
    finally:
        sys.path.remove(str(BENCH))


def drive(model: ModuleType, frames: int) -> object:
    return model.Drive(["road"] * frames, np.arange(frames, dtype=float))


RUNGS = HalvingSection(eta=3, rungs=3)  # 90 frames: rungs end at frames 9 and 29


def test_a_trial_pays_each_rung_at_the_share_that_reaches_it(model: ModuleType) -> None:
    costs = [np.ones(90)]
    mean, whole = model.study_cost([drive(model, 90)], costs, [0.5, 0.25], RUNGS, length_m=5)
    assert whole == 90
    assert mean == pytest.approx(10 + 0.5 * 20 + 0.5 * 0.25 * 60)


def test_a_rung_where_no_segment_has_ended_stops_no_trial(model: ModuleType) -> None:
    # L = 15 m: no segment has ended by frame 9 (9 m), so every trial runs on to rung 1
    mean, _ = model.study_cost([drive(model, 90)], [np.ones(90)], [0.5, 0.25], RUNGS,
                               length_m=15)
    assert mean == pytest.approx(10 + 20 + 0.25 * 60)


def test_the_protocol_adds_studies_joint_study_and_evaluated_runs(model: ModuleType) -> None:
    drives = {"a": drive(model, 90), "b": drive(model, 90)}  # "a" trained, both evaluated
    costs = {"road": model.Cost(cpu_default=0.5, wall_default=0.5, cpu_sampled=1.0, failed=0)}
    promotion = model.Promotion([0.5, 0.25], 0.0, 0, 0.0)
    plan = model.Plan(train=("a",), iterations=4, joint_iterations=2, length_m=5,
                      halving=RUNGS, workers=2)

    whole = model.protocol_cost(drives, costs, promotion, False, plan)
    assert (whole.studies_s, whole.joint_s) == (4 * 90, 2 * 90)
    assert whole.evaluate_s == 2 * 90 + 2 * (45 + 90)  # adaptive; baseline and fixed
    assert whole.core_s == 360 + 180 + 450
    # waves of 2 trials; the evaluated runs 2 at a time
    assert whole.wall_s == 2 * 90 + 1 * 90 + 90 + 135

    halved = model.protocol_cost(drives, costs, promotion, True, plan)
    trial = 10 + 0.5 * 20 + 0.5 * 0.25 * 60
    assert (halved.studies_s, halved.joint_s) == (pytest.approx(4 * trial),
                                                  pytest.approx(2 * trial))
    assert halved.evaluate_s == whole.evaluate_s  # evaluation is never cut
    # the work spread over the workers, plus one whole trial's tail
    assert halved.wall_s == pytest.approx((4 * trial / 2 + 90) + (2 * trial / 2 + 90) + 225)


def test_a_study_that_fits_the_scan_cache_pays_its_decoding_once_per_worker(
        model: ModuleType) -> None:
    # a frame: 0.25 s over cached scans, 0.1 s to decode, 1000 bytes decoded; "a": 90 kB
    drives = {"a": drive(model, 90)}
    costs = {"road": model.Cost(cpu_default=0.5, wall_default=0.5, cpu_sampled=1.0, failed=0,
                                cpu_cached=0.25, cpu_decode=0.1, bytes_per_frame=1000)}
    promotion = model.Promotion([], 0.0, 0, 0.0)

    def studies(memory_bytes: int) -> float:
        plan = model.Plan(train=("a",), iterations=4, joint_iterations=2, workers=2,
                          memory_bytes=memory_bytes)
        return model.protocol_cost(drives, costs, promotion, False, plan).studies_s

    # 1 MB for 2 workers: a cache of 250 kB each holds "a"; both workers decode it once
    assert studies(1_000_000) == pytest.approx(4 * 90 * 0.25 + 2 * 90 * 0.1)
    # 300 kB: 75 kB each, every trial reads the MCAP
    assert studies(300_000) == pytest.approx(4 * 90 * 1.0)


def test_trials_wait_at_a_rung_for_the_earlier_ones(model: ModuleType) -> None:
    """9 frames, rungs ending at frames 3 and 6, 2 workers, proposals lagging 3. Trial 0 runs
    whole at 2 s a frame (posts at 6 and 12 s, ends at 18 s); trial 1, whole at 1 s a frame,
    reaches the rungs at 3 and 9 s and waits 3 s at each for trial 0 (ends at 15 s); trial 2
    starts when trial 1 frees its worker and stops at rung 0 at 18 s without waiting."""
    schedule = model.rung_schedule([9, 9, 3], [2.0, 1.0, 1.0], [3, 6], 9, workers=2, lag=3)
    assert (schedule.makespan_s, schedule.work_s, schedule.waiting_s) == (18.0, 30.0, 6.0)
    # one worker: nothing is ever waited for, the trials run back to back
    serial = model.rung_schedule([9, 9, 3], [2.0, 1.0, 1.0], [3, 6], 9, workers=1, lag=1)
    assert (serial.makespan_s, serial.waiting_s) == (30.0, 0.0)


def test_the_measured_schedule_sets_the_halving_wall(model: ModuleType) -> None:
    drives = {"a": drive(model, 90)}
    costs = {"road": model.Cost(cpu_default=0.5, wall_default=0.5, cpu_sampled=1.0, failed=0)}
    plan = model.Plan(train=("a",), iterations=4, joint_iterations=2, length_m=5,
                      halving=RUNGS, workers=2)
    guessed = model.Promotion([0.5, 0.25], 0.0, 0, 0.0)  # no schedule: work / N + one tail
    measured = model.Promotion([0.5, 0.25], 0.0, 0, 0.0, waiting=0.2, makespan=1.5)
    trial = 10 + 0.5 * 20 + 0.5 * 0.25 * 60
    for halving in (False, True):
        a, b = (model.protocol_cost(drives, costs, p, halving, plan) for p in (guessed, measured))
        assert a.core_s == b.core_s  # the schedule costs wall time, no CPU
        if halving:  # the evaluated runs: 225 s either way
            assert b.wall_s == pytest.approx(1.5 * (4 + 2) * trial / 2 + 225)
        else:
            assert b.wall_s == a.wall_s
