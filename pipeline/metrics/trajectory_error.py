"""Errors of an estimated trajectory against a ground truth, for runs of any length.

- RTE: the pipeline's own per-start-frame relative error over ``length_m`` metres
  (pipeline.metrics.rte), averaged over the start frames: the number trials optimise.
- APE (as evo_ape): translation error [m] of every pose after aligning the estimate to the
  ground truth with Umeyama's method (rotation and translation; scale too with ``scale``).
- RPE (as evo_rpe): translation error [m] of the relative motion between consecutive frames.
APE and RPE give rmse, mean, median, std, min and max, as evo does.

Inputs: a sequence MCAP (its ground truth), a trajectory Parquet (``adaptune run``) or a pose
file of any format pipeline.posefile reads. Stamped poses on both sides are paired by
the nearest stamp within 10 ms (evo's default); otherwise pose k pairs with pose k.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3, path_distances
from pipeline.metrics.rte import per_frame_rte
from pipeline.posefile import PoseFormat, read_pose_file

F64 = NDArray[np.float64]
MAX_STAMP_DIFF_NS = 10_000_000
"""Stamped poses pair with the nearest stamp within 10 ms (evo's max_diff 0.01 s)."""


@dataclass(frozen=True)
class Poses:
    """(N, 4, 4) poses and their (N,) stamps [ns] where the source has them."""

    what: str
    T: F64
    stamps_ns: NDArray[np.int64] | None


def load_poses(path: str | Path, fmt: PoseFormat = "auto") -> Poses:
    """The poses of a sequence MCAP (ground truth), a trajectory Parquet or a pose file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        from pipeline.sequence import SequenceReader

        with SequenceReader(path) as reader:
            gt = reader.require_ground_truth("to compare with")
            return Poses(str(path), gt, reader.stamps_ns.copy())
    if suffix == ".parquet":
        from pipeline.trajectory import read_trajectory

        traj = read_trajectory(path)
        return Poses(str(path), traj.T_world_lidar, traj.stamps_ns)
    pf = read_pose_file(path, fmt)
    return Poses(str(path), pf.T_world_x, pf.stamps_ns)


def associate(gt: Poses, est: Poses) -> tuple[F64, F64]:
    """Paired (M, 4, 4) ground-truth and estimated poses (module docstring)."""
    if gt.stamps_ns is None or est.stamps_ns is None:
        if len(gt.T) != len(est.T):
            raise InputError(f"{est.what}: {len(est.T)} poses, the ground truth {gt.what} has "
                             f"{len(gt.T)} (without stamps on both sides, pose k pairs with "
                             "pose k)")
        return gt.T, est.T
    idx = np.clip(np.searchsorted(gt.stamps_ns, est.stamps_ns), 1, max(len(gt.T) - 1, 1))
    before = np.abs(est.stamps_ns - gt.stamps_ns[idx - 1])
    after = np.abs(est.stamps_ns - gt.stamps_ns[np.minimum(idx, len(gt.T) - 1)])
    nearest = np.where(before <= after, idx - 1, np.minimum(idx, len(gt.T) - 1))
    ok = np.minimum(before, after) <= MAX_STAMP_DIFF_NS
    ok &= np.concatenate([[True], np.diff(nearest) > 0])  # each ground-truth pose once
    if ok.sum() < 2:
        raise InputError(f"{est.what}: fewer than 2 poses within 10 ms of a ground-truth stamp "
                         f"in {gt.what}")
    return gt.T[nearest[ok]], est.T[ok]


def umeyama(src: F64, dst: F64, scale: bool) -> tuple[F64, F64, float]:
    """(R (3, 3), t (3,), s) minimising sum |dst - (s R src + t)|^2 over (M, 3) point sets
    (Umeyama 1991; the rotation is scipy's Kabsch solution, a proper rotation)."""
    from scipy.spatial.transform import Rotation

    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    if len(src) < 3 or np.abs(a).max() == 0:
        return np.eye(3), mu_d - mu_s, 1.0
    with warnings.catch_warnings():  # collinear points: every rotation about their line is
        # optimal, and gives the same residuals (the APE); scipy warns and picks one
        warnings.filterwarnings("ignore", "Optimal rotation is not uniquely", UserWarning)
        R = Rotation.align_vectors(b, a)[0].as_matrix()
    s = float(np.einsum("ij,ij->", b, a @ R.T) / np.einsum("ij,ij->", a, a)) if scale else 1.0
    return R, mu_d - s * R @ mu_s, s


def _stats(err: F64) -> dict[str, float]:
    return {"rmse": float(np.sqrt(np.mean(err**2))), "mean": float(err.mean()),
            "median": float(np.median(err)), "std": float(err.std()),
            "min": float(err.min()), "max": float(err.max())}


def trajectory_errors(gt: F64, est: F64, length_m: float, scale: bool = False) -> dict[str, Any]:
    """RTE over ``length_m``, APE after Umeyama alignment (Sim(3) with ``scale``) and RPE
    between consecutive frames of paired (M, 4, 4) poses; JSON-ready."""
    path = path_distances(gt)
    if path[-1] <= length_m:
        raise InputError(f"the ground truth runs {path[-1]:.2f} m, not longer than "
                         f"--length {length_m:g} m: no sub-trajectory to score")
    t_err, r_err = per_frame_rte(gt, est, length_m)
    ok = np.isfinite(t_err)
    R, t, s = umeyama(est[:, :3, 3], gt[:, :3, 3], scale)
    aligned = est.copy()
    aligned[:, :3, :3] = R @ est[:, :3, :3]
    aligned[:, :3, 3] = s * est[:, :3, 3] @ R.T + t
    ape = np.linalg.norm(aligned[:, :3, 3] - gt[:, :3, 3], axis=1)
    d_gt = inv_se3(gt[:-1]) @ gt[1:]
    d_est = inv_se3(aligned[:-1]) @ aligned[1:]
    rpe = np.linalg.norm((inv_se3(d_gt) @ d_est)[:, :3, 3], axis=1)
    return {
        "frames": len(gt), "path_m": float(path[-1]),
        "rte": {"length_m": float(length_m), "segments": int(ok.sum()),
                "t_err_pct": float(t_err[ok].mean()),
                "r_err_deg_per_m": float(np.degrees(r_err[ok].mean())),
                "t_err_pct_median": float(np.median(t_err[ok])),
                "t_err_pct_max": float(t_err[ok].max())},
        "ape": {"alignment": "sim3" if scale else "se3", "scale": s, **_stats(ape)},
        "rpe": {"delta_frames": 1, **_stats(rpe)},
    }


def evaluate_files(gt_path: str | Path, est_path: str | Path, length_m: float,
                   scale: bool = False, gt_format: PoseFormat = "auto",
                   est_format: PoseFormat = "auto") -> dict[str, Any]:
    """``trajectory_errors`` of two files (module docstring: which files)."""
    if not length_m > 0:
        raise InputError(f"--length must be > 0 m, got {length_m}")
    gt, est = associate(load_poses(gt_path, gt_format), load_poses(est_path, est_format))
    if not (np.isfinite(gt).all() and np.isfinite(est).all()):
        raise InputError(f"{est_path}: a pose is not finite")
    return {"ground_truth": str(gt_path), "estimate": str(est_path),
            **trajectory_errors(gt, est, length_m, scale)}
