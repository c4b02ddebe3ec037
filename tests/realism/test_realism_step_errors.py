"""The frame-to-frame error of the sim-to-real comparison (docs/design.md, "The sim-to-real
comparison"): E = inv(inv(G_i) G_i+1) inv(P_i) P_i+1, its translation in cm and its rotation
angle in deg, against cases worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from pipeline.errors import InputError
from studies.realism.registration import step_errors

F64 = NDArray[np.float64]


def pose(yaw_deg: float = 0.0, t: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> F64:
    """A (4, 4) rigid transform: rotation ``yaw_deg`` about z, translation ``t`` [m]."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T


def chain(steps: list[F64], start: F64 | None = None) -> F64:
    """(len(steps) + 1, 4, 4) poses: ``start`` (identity) then each relative step applied."""
    poses = [np.eye(4) if start is None else start]
    for step in steps:
        poses.append(poses[-1] @ step)
    return np.stack(poses)


def test_a_step_2_cm_too_long_is_2_cm_and_0_deg() -> None:
    G = chain([pose(t=(1.0, 0, 0))])
    P = chain([pose(t=(1.02, 0, 0))])
    t_cm, r_deg = step_errors(G, P)
    assert t_cm == pytest.approx([2.0])
    assert r_deg == pytest.approx([0.0], abs=1e-9)


def test_a_step_turned_half_a_degree_too_far_is_0_5_deg_and_0_cm() -> None:
    G = chain([pose(10.0, (1.0, 0, 0))])
    P = chain([pose(10.5, (1.0, 0, 0))])
    t_cm, r_deg = step_errors(G, P)
    assert r_deg == pytest.approx([0.5])
    assert t_cm == pytest.approx([0.0], abs=1e-9)


def test_the_translation_error_is_in_the_frame_of_the_step_start() -> None:
    """G step: 90 deg turn and 1 m forward; P step: the same turn, 1 m forward and 3 cm to the
    left. E = [I, R^T (t_P - t_G)]: 3 cm, whatever the pose the step starts from (the world
    frames of G and P differ: the estimate starts at the identity)."""
    start = pose(37.0, (5.0, -2.0, 0.3))
    G = chain([pose(90.0, (1.0, 0, 0)), pose(0.0, (1.0, 0, 0))], start)
    P = chain([pose(90.0, (1.0, 0.03, 0)), pose(0.0, (1.0, 0, 0))])
    t_cm, r_deg = step_errors(G, P)
    assert t_cm == pytest.approx([3.0, 0.0], abs=1e-9)
    assert r_deg == pytest.approx([0.0, 0.0], abs=1e-6)


def test_every_step_is_scored_on_its_own_not_the_drift_so_far() -> None:
    """Step 1 is 4 cm short and turned 1 deg too far; step 2 is exact: its error is 0 however
    far off the estimate already is (a trajectory error would grow)."""
    G = chain([pose(0.0, (1.0, 0, 0)), pose(0.0, (1.0, 0, 0))])
    P = chain([pose(1.0, (0.96, 0, 0)), pose(0.0, (1.0, 0, 0))])
    t_cm, r_deg = step_errors(G, P)
    assert t_cm == pytest.approx([4.0, 0.0], abs=1e-9)
    assert r_deg == pytest.approx([1.0, 0.0], abs=1e-6)


def test_stacks_that_do_not_pair_are_refused() -> None:
    with pytest.raises(InputError, match="estimate has 2 poses, ground truth has 3"):
        step_errors(chain([pose(), pose()]), chain([pose()]))
    with pytest.raises(InputError, match="at least 2 poses, got 1"):
        step_errors(np.eye(4)[None], np.eye(4)[None])


def test_a_small_rotation_error_survives_ground_truth_orthonormal_to_2_5e_7() -> None:
    """KITTI's ground-truth rotations are orthonormal to about 2.5e-7 (their 12 printed
    digits): scaled by 1 + 2.5e-7 here. A 0.01 deg step error must still read 0.01 deg (the
    arccos of E's trace reads 0 deg for it)."""
    G = chain([pose(5.0, (1.0, 0, 0)), pose(5.0, (1.0, 0, 0))])
    G[:, :3, :3] *= 1.0 + 2.5e-7
    P = chain([pose(5.01, (1.0, 0, 0)), pose(5.0, (1.0, 0, 0))])
    _, r_deg = step_errors(G, P)
    assert r_deg == pytest.approx([0.01, 0.0], abs=1e-4)
