"""Frame-to-frame registration error of an odometry run against the ground truth.

For consecutive frames i, i + 1 with ground truth G and estimate P (T_world_lidar), the error
of one step is E = inv(inv(G_i) G_i+1) inv(P_i) P_i+1; its translation [cm] and rotation
angle [deg] are the step's errors.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3, rotation_angle
from pipeline.odometry.base import Schedule
from pipeline.odometry.registry import get_adapter
from pipeline.sequence import Scan

F64 = NDArray[np.float64]


def step_errors(T_gt: F64, T_est: F64) -> tuple[F64, F64]:
    """((N - 1,) translational error [cm], (N - 1,) rotational error [deg]) of every step
    between the (N, 4, 4) ground truth and estimate."""
    rel_gt = inv_se3(T_gt[:-1]) @ T_gt[1:]
    rel_est = inv_se3(T_est[:-1]) @ T_est[1:]
    E = inv_se3(rel_gt) @ rel_est
    return (100.0 * np.linalg.norm(E[:, :3, 3], axis=1),
            np.rad2deg(rotation_angle(E[:, :3, :3])))


def odometry_step_errors(algorithm: str, scans: list[Scan]) -> tuple[F64, F64]:
    """Step errors (``step_errors``) of ``algorithm`` at its default parameters over ``scans``
    (each with its ground truth)."""
    adapter = get_adapter(algorithm)
    traj = adapter.run(scans, Schedule.constant(adapter.space.defaults(), len(scans)))
    T_gt = np.stack([s.T_world_lidar for s in scans if s.T_world_lidar is not None])
    if len(T_gt) != len(scans):
        raise InputError("every scan of a realism slice needs its ground truth")
    return step_errors(T_gt, traj.T_world_lidar)
