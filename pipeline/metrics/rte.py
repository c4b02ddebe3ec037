"""Relative trajectory error (RTE) of sub-trajectories, vectorised with numpy.

The paper's y_ij: for every start frame i, the sub-trajectory that runs ``length_m`` metres
along the ground truth; it ends at the first frame whose path distance is strictly greater
than dist[i] + length_m (the KITTI devkit's rule). With dGT = inv(GT_i) GT_j and
dEst = inv(Est_i) Est_j, E = inv(dEst) dGT; translational RTE = |E.t| / length_m * 100 [%],
rotational RTE = angle(E.R) / length_m [rad/m]. Frames without ``length_m`` of ground truth
ahead have no segment (NaN).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3, path_distances, rotation_angle

F64 = NDArray[np.float64]


def segment_ends(dist_m: F64, length_m: float) -> NDArray[np.int64]:
    """Index of the last frame of the segment starting at every frame; -1 where none.

    dist_m: (N,) non-decreasing path distances [m]. Returns (N,) int64.
    """
    ends = np.searchsorted(dist_m, dist_m + length_m, side="right")
    return np.where(ends < len(dist_m), ends, -1).astype(np.int64)


def check_scorable(gt: F64, length_m: float, what: str) -> None:
    """InputError unless the ground truth ``gt`` (N, 4, 4) runs longer than ``length_m``: an
    RTE of that length needs at least one segment (a shorter sequence has no score at all)."""
    total_m = float(path_distances(gt)[-1]) if len(gt) else 0.0
    if not total_m > length_m:
        raise InputError(f"{what}: ground truth runs {total_m:.1f} m, not longer than "
                         f"length_m={length_m}: no RTE segment to score")


def check_pair(gt: F64, est: F64) -> None:
    """Raise InputError unless ``gt`` and ``est`` are finite (N, 4, 4) stacks of equal N."""
    if gt.ndim != 3 or gt.shape[1:] != (4, 4) or est.ndim != 3 or est.shape[1:] != (4, 4):
        raise InputError(f"poses must be (N, 4, 4), got ground truth {gt.shape}, "
                         f"estimate {est.shape}")
    if len(gt) != len(est):
        raise InputError(f"estimate has {len(est)} poses, ground truth has {len(gt)}")
    if not np.isfinite(est).all():
        bad = int(np.argmax(~np.isfinite(est).reshape(len(est), -1).all(axis=1)))
        raise InputError(f"estimate has a non-finite pose at frame {bad}")
    if not np.isfinite(gt).all():
        raise InputError("ground truth has a non-finite pose")


def per_frame_rte(gt: F64, est: F64, length_m: float) -> tuple[F64, F64]:
    """(t_err_pct, r_err_rad_per_m), each (N,), NaN for frames without a segment.

    gt, est: (N, 4, 4) T_world_lidar of the same frames.
    """
    check_pair(gt, est)
    ends = segment_ends(path_distances(gt), length_m)
    t_err = np.full(len(gt), np.nan)
    r_err = np.full(len(gt), np.nan)
    i = np.flatnonzero(ends >= 0)
    if len(i):
        j = ends[i]
        d_gt = inv_se3(gt[i]) @ gt[j]
        d_est = inv_se3(est[i]) @ est[j]
        E = inv_se3(d_est) @ d_gt
        t_err[i] = np.linalg.norm(E[:, :3, 3], axis=1) / length_m * 100.0
        r_err[i] = rotation_angle(E[:, :3, :3]) / length_m
    return t_err, r_err


def mean_rte_pct(gt: F64, est: F64, length_m: float) -> float:
    """Mean translational RTE [%] over all start frames that have a segment (NaN if none)."""
    t_err, _ = per_frame_rte(gt, est, length_m)
    valid = t_err[np.isfinite(t_err)]
    return float(valid.mean()) if len(valid) else float("nan")
