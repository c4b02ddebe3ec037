"""The contract every registered odometry adapter passes (parametrised over the registry).

Stated accuracy (final pose of the run vs ground truth, both relative to frame 0):
- synthetic yard, 20 frames, 15.3 m: translation < 0.30 m (2 %), rotation < 1.5 deg;
- real KITTI 04 frames 0-9, 11.9 m: translation < 0.25 m (2 %), rotation < 0.5 deg.
(Measured: ndt 0.03 m / 0.35 deg, gicp 0.03 / 0.06, kiss_icp 0.15 / 0.98, command 0.03 / 0.20
on the yard; on KITTI 04 all within 0.12 m. On KITTI 06 every adapter ends 0.85-0.94 deg off
the official ground truth in the same direction, so 04 is used.)
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.odometry_data import Seq, final_errors, make_adapter

from pipeline.errors import ConfigError, InputError
from pipeline.odometry import adapter_names, run_sequence
from pipeline.odometry.base import (
    Adapter,
    Schedule,
    StreamingAdapter,
    TimeLimitedAdapter,
    WarmableAdapter,
)

MAX_T_ERR_M = 0.30
MAX_R_ERR_DEG = 1.5
KITTI_MAX_T_ERR_M = 0.25
KITTI_MAX_R_ERR_DEG = 0.5


def changed_params(adapter) -> dict[str, float]:
    """Valid parameters that differ from the baseline in every parameter (towards the middle)."""
    out = {}
    for s in adapter.space.specs:
        mid = s.low + 0.5 * (s.high - s.low) if not s.log else float(np.sqrt(s.low * s.high))
        v = s.default + 0.5 * (mid - s.default) if mid != s.default else s.default * 0.75
        out[s.name] = float(round(v)) if s.kind == "int" else float(v)
    return adapter.space.validate(out)


def schedule_with_switch(adapter, n: int, k: int) -> Schedule:
    """Baseline for frames 0..k-1, ``changed_params`` from frame k on."""
    base, new = adapter.space.defaults(), changed_params(adapter)
    before = np.arange(n) < k
    return Schedule(np.arange(n, dtype=np.int32),
                    {p: np.where(before, base[p], new[p]).astype(np.float64) for p in base})


_cache: dict[tuple[str, str], np.ndarray] = {}


def baseline_run(adapter, seq: Seq) -> np.ndarray:
    """T_world_lidar (N, 4, 4) of the adapter's baseline on ``seq`` (cached per test session)."""
    key = (adapter.name, str(seq.path))
    if key not in _cache:
        traj = run_sequence(adapter, seq.path, adapter.space.defaults())
        _cache[key] = traj.T_world_lidar
    return _cache[key]


def test_registry_lists_every_adapter() -> None:
    assert adapter_names() == ["ndt", "gicp", "kiss_icp", "command"]


def test_unknown_adapter_is_a_config_error() -> None:
    from pipeline.odometry import get_adapter

    with pytest.raises(ConfigError, match=r"unknown odometry algorithm 'loam' \(known: ndt, gicp"):
        get_adapter("loam")


def test_space_defaults_are_valid(adapter) -> None:
    assert adapter.space.validate({}) == adapter.space.defaults()
    assert adapter.space.names


def test_synthetic_accuracy(adapter, synthetic_seq: Seq) -> None:
    est = baseline_run(adapter, synthetic_seq)
    assert est.shape == (len(synthetic_seq), 4, 4)
    np.testing.assert_allclose(est[0], np.eye(4), atol=1e-9)
    t_err, r_err = final_errors(est, synthetic_seq.gt)
    assert t_err < MAX_T_ERR_M, f"{adapter.name}: final translation error {t_err:.3f} m"
    assert r_err < MAX_R_ERR_DEG, f"{adapter.name}: final rotation error {r_err:.3f} deg"


def test_kitti_accuracy(adapter, kitti_seq: Seq) -> None:
    est = baseline_run(adapter, kitti_seq)
    t_err, r_err = final_errors(est, kitti_seq.gt)
    travelled = float(np.linalg.norm(np.diff(kitti_seq.gt[:, :3, 3], axis=0), axis=1).sum())
    assert travelled > 10.0
    assert t_err < KITTI_MAX_T_ERR_M, f"{adapter.name}: final translation error {t_err:.3f} m"
    assert r_err < KITTI_MAX_R_ERR_DEG, f"{adapter.name}: final rotation error {r_err:.3f} deg"


def test_constant_schedule_reproduces_the_fixed_run_bitwise(adapter, synthetic_seq: Seq) -> None:
    """A constant Schedule == the fixed-parameter run, bit for bit."""
    params = adapter.space.defaults()
    fixed = baseline_run(adapter, synthetic_seq)
    if isinstance(adapter, StreamingAdapter):
        # the fixed run without any schedule machinery: one odometry, stepped by hand
        odom = adapter.start(params)
        fixed = np.stack([odom.step(s.xyz, s.stamp_ns) for s in synthetic_seq.scans])
    scheduled = adapter.run(synthetic_seq.scans, Schedule.constant(params, len(synthetic_seq)))
    assert np.array_equal(scheduled.T_world_lidar, fixed)


def test_mid_run_change_is_continuous(adapter, synthetic_seq: Seq) -> None:
    """Switching parameters at frame k: identical before k, different after, no jump at k."""
    n, k = len(synthetic_seq), len(synthetic_seq) // 2
    schedule = schedule_with_switch(adapter, n, k)
    assert schedule.changes() == [0, k]
    est = run_sequence(adapter, synthetic_seq.path, schedule).T_world_lidar
    const = baseline_run(adapter, synthetic_seq)
    assert np.array_equal(est[:k], const[:k]), "frames before the switch must not change"
    assert not np.array_equal(est[k:], const[k:]), "the new parameters had no effect"
    gt = synthetic_seq.gt
    step_est = np.linalg.inv(est[k - 1]) @ est[k]
    step_gt = np.linalg.inv(gt[k - 1]) @ gt[k]
    jump = float(np.linalg.norm(step_est[:3, 3] - step_gt[:3, 3]))
    assert jump < 0.05, f"{adapter.name}: step at the switch is off by {jump:.3f} m"
    t_err, _ = final_errors(est, gt)
    assert t_err < MAX_T_ERR_M


@pytest.mark.parametrize("name", adapter_names())
def test_unknown_or_out_of_range_parameter_is_a_config_error(name: str, synthetic_seq: Seq) -> None:
    adapter = make_adapter(name)
    with pytest.raises(ConfigError, match=r"unknown parameter 'bogus' \(known: "):
        run_sequence(adapter, synthetic_seq.path, {"bogus": 1.0})
    spec = adapter.space.specs[0]
    with pytest.raises(ConfigError, match=rf"{spec.name} must be in \["):
        run_sequence(adapter, synthetic_seq.path, {spec.name: spec.high + 1.0})
    if isinstance(adapter, StreamingAdapter):
        with pytest.raises(ConfigError, match=rf"{spec.name} must be in \["):
            adapter.start({spec.name: spec.low - 1.0})
        odom = adapter.start({})
        with pytest.raises(ConfigError, match="unknown parameter 'bogus'"):
            odom.set_params({"bogus": 1.0})


def test_bad_schedule_is_an_input_error(adapter, synthetic_seq: Seq) -> None:
    n = len(synthetic_seq)
    short = Schedule.constant(adapter.space.defaults(), n - 1)
    with pytest.raises(InputError, match=f"covers {n - 1} frames, the sequence has {n}"):
        run_sequence(adapter, synthetic_seq.path, short)
    bad = Schedule.constant(adapter.space.defaults(), n)
    spec = adapter.space.specs[0]
    bad.values[spec.name][3] = spec.high * 2 + 1
    with pytest.raises(InputError, match=f"{spec.name} must be in .* at frame 3"):
        run_sequence(adapter, synthetic_seq.path, bad)


def test_unknown_adapter_option_is_a_config_error() -> None:
    for name in ("ndt", "gicp", "kiss_icp"):
        with pytest.raises(ConfigError, match=r"option\.bogus: unknown parameter"):
            make_adapter(name).__class__(bogus=1)


@pytest.mark.parametrize("name", adapter_names())
def test_what_callers_use_is_declared(name: str) -> None:
    """``start``, ``warm`` and ``accepts_time_limit`` are Protocols of pipeline/odometry/base.py:
    an adapter offering one is an instance of its Protocol, and the other way round."""
    adapter = make_adapter(name)
    assert isinstance(adapter, Adapter)
    for protocol, member in ((StreamingAdapter, "start"), (WarmableAdapter, "warm"),
                             (TimeLimitedAdapter, "accepts_time_limit")):
        assert isinstance(adapter, protocol) == hasattr(adapter, member), (name, member)
    # every adapter either streams in process or runs a whole sequence under its own limit
    assert isinstance(adapter, StreamingAdapter) != isinstance(adapter, TimeLimitedAdapter)
