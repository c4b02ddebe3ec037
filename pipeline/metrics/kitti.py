"""The KITTI odometry devkit metric, exactly as ``calcSequenceErrors`` in evaluate_odometry.cpp.

For every start frame 0, 10, 20, ... (``STEP_FRAMES``) and every length 100, 200, ..., 800 m:
the segment ends at the first frame whose ground-truth path distance is strictly greater than
dist[first] + length (no segment when the sequence is too short);
dGT = inv(GT_first) GT_last, dEst = inv(Est_first) Est_last, E = inv(dEst) dGT;
t_err = |E.t| / length [fraction], r_err = angle(E.R) / length [rad/m].
The sequence (or benchmark) result is the mean over all segments, pooled over all sequences.

As in the devkit, inverses are general 4x4 inverses (the official pose files carry 7 digits,
so their rotations are orthonormal only to ~1e-7) and path distances are accumulated frame by
frame. Vectorised: every segment of a sequence is computed in one batch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

F64 = NDArray[np.float64]

LENGTHS_M: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
"""The devkit's segment lengths [m]."""

STEP_FRAMES = 10
"""The devkit evaluates a segment start every 10 frames (every second at 10 Hz)."""


@dataclass(frozen=True)
class KittiSegments:
    """Devkit segments of one or more sequences, one entry per segment (M,).

    first_frame, last_frame: int64 frame indices; length_m: segment length [m];
    t_err: |E.t| / length (fraction); r_err: angle(E.R) / length [rad/m];
    speed_mps: length / (0.1 s * frames), as the devkit reports it.
    """

    first_frame: NDArray[np.int64]
    last_frame: NDArray[np.int64]
    length_m: F64
    t_err: F64
    r_err: F64
    speed_mps: F64

    def __len__(self) -> int:
        return len(self.first_frame)

    @property
    def t_err_pct(self) -> float:
        """Mean translational error [%] over all segments (NaN when there is none)."""
        return float(self.t_err.mean() * 100.0) if len(self) else float("nan")

    @property
    def r_err_deg_per_m(self) -> float:
        """Mean rotational error [deg/m] over all segments (NaN when there is none)."""
        return float(np.degrees(self.r_err.mean())) if len(self) else float("nan")

    @classmethod
    def concat(cls, parts: Sequence[KittiSegments]) -> KittiSegments:
        """Pool the segments of several sequences (the benchmark's overall mean)."""
        if not parts:
            return sequence_segments_empty()
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))


_FIELDS = ("first_frame", "last_frame", "length_m", "t_err", "r_err", "speed_mps")


def sequence_segments_empty() -> KittiSegments:
    """A KittiSegments without any segment."""
    i, f = np.zeros(0, np.int64), np.zeros(0)
    return KittiSegments(i, i.copy(), f, f.copy(), f.copy(), f.copy())


def kitti_errors(gt: F64, est: F64, lengths_m: Sequence[float] = LENGTHS_M,
                 step_frames: int = STEP_FRAMES) -> KittiSegments:
    """Devkit segments of one sequence. gt, est: (N, 4, 4) poses of the same frames."""
    check_poses(gt, "ground truth")
    check_poses(est, "estimate")
    if len(est) != len(gt):
        raise InputError(f"estimate has {len(est)} poses, ground truth has {len(gt)}")
    dist = trajectory_distances(gt)
    first_all = np.arange(0, len(gt), step_frames, dtype=np.int64)
    firsts, lasts, lens = [], [], []
    for length in lengths_m:  # devkit order: first frame major, length minor (kept below)
        last = last_frames(dist, first_all, float(length))
        ok = last >= 0
        firsts.append(first_all[ok])
        lasts.append(last[ok])
        lens.append(np.full(int(ok.sum()), float(length)))
    first, last, length_m = (np.concatenate(x) for x in (firsts, lasts, lens))
    order = np.lexsort((np.searchsorted(np.asarray(lengths_m, float), length_m), first))
    first, last, length_m = first[order], last[order], length_m[order]
    R, t = segment_error_poses(gt, est, first, last)
    t_err = np.sqrt(t[:, 0, 0] ** 2 + t[:, 1, 0] ** 2 + t[:, 2, 0] ** 2) / length_m
    r_err = rotation_error(R) / length_m
    speed = length_m / (0.1 * (last - first + 1))
    return KittiSegments(first, last, length_m, t_err, r_err, speed)


def kitti_sequence_error(gt: F64, est: F64) -> tuple[float, float]:
    """(t_err [%], r_err [deg/m]) of one sequence: the devkit mean over its segments."""
    seg = kitti_errors(gt, est)
    return seg.t_err_pct, seg.r_err_deg_per_m


def trajectory_distances(poses: F64) -> F64:
    """(N,) path distance [m] from frame 0, accumulated frame by frame as the devkit does."""
    d = np.diff(poses[:, :3, 3], axis=0)
    step = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    return np.concatenate([[0.0], np.cumsum(step)])


def last_frames(dist_m: F64, first: NDArray[np.int64], length_m: float) -> NDArray[np.int64]:
    """First frame with dist > dist[first] + length_m for every start; -1 where none."""
    last = np.searchsorted(dist_m, dist_m[first] + length_m, side="right")
    return np.where(last < len(dist_m), last, -1).astype(np.int64)


RT = tuple[F64, F64]
"""An affine transform stack as (A (M, 3, 3), t (M, 3, 1)), contiguous for fast matmul."""


def segment_error_poses(gt: F64, est: F64, first: NDArray[np.int64],
                        last: NDArray[np.int64]) -> RT:
    """E = inv(dEst) dGT of every segment as (R (M, 3, 3), t (M, 3, 1)); general inverses."""
    starts, idx = np.unique(first, return_inverse=True)
    d_gt = compose(take(inverse(split(gt[starts])), idx), split(gt[last]))
    d_est = compose(take(inverse(split(est[starts])), idx), split(est[last]))
    return compose(inverse(d_est), d_gt)


def split(T: F64) -> RT:
    """(A, t) of (M, 4, 4) transforms."""
    return np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3:4])


def take(T: RT, idx: NDArray[np.int64]) -> RT:
    """Rows ``idx`` of an (A, t) stack."""
    return T[0][idx], T[1][idx]


def inverse(T: RT) -> RT:
    """General inverse [A^-1, -A^-1 t] of an (A, t) stack.

    A^-1 by cofactors (adjugate / determinant), as Eigen inverts small fixed-size matrices;
    not the rigid shortcut A^T, so slightly non-orthonormal rotations are inverted exactly.
    """
    a = T[0]
    cof = np.empty_like(a)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            cof[:, j, i] = a[:, i1, j1] * a[:, i2, j2] - a[:, i1, j2] * a[:, i2, j1]
    det = a[:, 0, 0] * cof[:, 0, 0] + a[:, 0, 1] * cof[:, 1, 0] + a[:, 0, 2] * cof[:, 2, 0]
    a_inv = cof / det[:, None, None]
    return a_inv, -(a_inv @ T[1])


def compose(A: RT, B: RT) -> RT:
    """Product A B of two (A, t) stacks."""
    return A[0] @ B[0], A[0] @ B[1] + A[1]


def rotation_error(R: F64) -> F64:
    """(M,) rotation angle [rad] of rotations (M, 3, 3), as the devkit's rotationError."""
    d = 0.5 * (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1.0)
    return np.arccos(np.clip(d, -1.0, 1.0))


def check_poses(poses: F64, what: str) -> None:
    """Raise InputError unless ``poses`` is a finite (N, 4, 4) stack."""
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise InputError(f"{what}: poses must be (N, 4, 4), got {poses.shape}")
    finite = np.isfinite(poses).reshape(len(poses), -1).all(axis=1)
    if not finite.all():
        raise InputError(f"{what}: non-finite pose at frame {int(np.argmin(finite))}")


def evaluate_kitti_files(gt_path: str | Path, est_path: str | Path,
                         lengths_m: Sequence[float] = LENGTHS_M,
                         step_frames: int = STEP_FRAMES) -> dict[str, Any]:
    """The devkit metric of two KITTI pose files (camera frame, as the benchmark ships them),
    over segments of ``lengths_m`` (any lengths: short runs take short ones) starting every
    ``step_frames`` frames.

    Returns {"t_err_pct", "r_err_deg_per_m", "segments", "frames", "per_length": {length:
    {"t_err_pct", "r_err_deg_per_m", "segments"}}}. InputError names the file when the files
    disagree in length, hold a non-finite pose, or the path is too short for any segment.
    """
    from pipeline.posefile import read_kitti_poses

    gt, est = read_kitti_poses(gt_path), read_kitti_poses(est_path)
    if len(est) != len(gt):
        raise InputError(f"{est_path}: estimate has {len(est)} poses, "
                         f"ground truth {gt_path} has {len(gt)}")
    seg = kitti_errors(gt, est, lengths_m, step_frames)
    if not len(seg):
        total = float(trajectory_distances(gt)[-1])
        raise InputError(f"{gt_path}: path is {total:.1f} m long, too short for a "
                         f"{min(lengths_m):g} m segment (shorter segment lengths: --lengths)")
    per_length = {}
    for length in lengths_m:
        m = seg.length_m == float(length)
        if m.any():
            per_length[f"{length:g}"] = {
                "t_err_pct": float(seg.t_err[m].mean() * 100.0),
                "r_err_deg_per_m": float(np.degrees(seg.r_err[m].mean())),
                "segments": int(m.sum()),
            }
    return {"t_err_pct": seg.t_err_pct, "r_err_deg_per_m": seg.r_err_deg_per_m,
            "segments": len(seg), "frames": len(gt), "per_length": per_length}
