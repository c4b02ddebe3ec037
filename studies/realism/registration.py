"""Frame-to-frame registration error of an odometry run against the ground truth
(docs/design.md, "The sim-to-real comparison").

For consecutive frames i, i + 1 with ground truth G and estimate P (T_world_lidar), the error
of one step is E = inv(inv(G_i) G_i+1) inv(P_i) P_i+1; its translation [cm] and rotation
angle [deg] are the step's errors. ``studies.realism.ground_truth`` compares the errors E
of two odometries and adds the ground truth's own error to them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.metrics.rte import check_pair
from pipeline.metrics.trajectory_error import pose_error_sizes, rpe_error_poses
from pipeline.odometry import run_scans
from pipeline.odometry.registry import build_adapter
from pipeline.sequence import Scan

F64 = NDArray[np.float64]


def step_error_poses(T_gt: F64, T_est: F64) -> F64:
    """(N - 1, 4, 4) error E of every step between the (N, 4, 4) ground truth and estimate
    (T_world_lidar): the relative pose error of one frame (``rpe_error_poses`` of the pairs
    (i, i + 1)). InputError for stacks that do not pair, or fewer than 2 poses."""
    check_pair(T_gt, T_est)
    if len(T_gt) < 2:
        raise InputError(f"step errors need at least 2 poses, got {len(T_gt)}")
    first = np.arange(len(T_gt) - 1, dtype=np.int64)
    return rpe_error_poses(T_gt, T_est, first, first + 1)


def error_sizes(E: F64) -> tuple[F64, F64]:
    """((N,) translational error [cm], (N,) rotational error [deg]) of step errors E
    (N, 4, 4)."""
    t_m, r_deg = pose_error_sizes(E)
    return 100.0 * t_m, r_deg


def step_errors(T_gt: F64, T_est: F64) -> tuple[F64, F64]:
    """``error_sizes`` of the steps between the ground truth and the estimate
    (``step_error_poses``)."""
    return error_sizes(step_error_poses(T_gt, T_est))


def odometry_step_errors(algorithm: str, scans: list[Scan], what: str) -> F64:
    """(N - 1, 4, 4) step errors (``step_error_poses``) of ``algorithm`` at its default
    parameters over ``scans`` (each with its ground truth; ``what`` names them in errors).
    OdometryError for a failed run, InputError for a scan without ground truth."""
    return step_error_poses(*odometry_trajectory(algorithm, scans, what))


def odometry_trajectory(algorithm: str, scans: list[Scan], what: str) -> tuple[F64, F64]:
    """(ground truth, estimate), both (N, 4, 4) T_world_lidar, of ``algorithm`` at its default
    parameters over the N ``scans`` (each with its ground truth; ``what`` names them in
    errors). OdometryError for a failed run, InputError for a scan without ground truth."""
    T_gt = [s.T_world_lidar for s in scans]
    if any(T is None for T in T_gt):
        raise InputError(f"{what}: every scan of a realism slice needs its ground truth")
    adapter = build_adapter(algorithm)
    stamps_ns = np.array([s.stamp_ns for s in scans], np.int64)
    traj = run_scans(adapter, scans, stamps_ns, adapter.space.defaults(), what)
    return np.stack(T_gt), traj.T_world_lidar  # type: ignore[arg-type]
