"""Errors of an estimated trajectory against a ground truth, for runs of any length, as evo
computes them (evo_ape, evo_rpe; tests/metrics/test_trajectory_error.py checks each against
evo's Python API).

- RTE: the pipeline's own per-start-frame relative error over ``length_m`` metres
  (pipeline.metrics.rte), averaged over the start frames: the number trials optimise. It is
  taken on the estimate as given (no alignment).
- Alignment of the estimate to the ground truth (evo's ``-a`` / ``-as`` / ``-s`` /
  ``--align_origin``): ``none``; ``origin`` (its first pose onto the ground truth's first
  pose); ``se3`` (Umeyama: rotation and translation fitted to every position); ``sim3``
  (Umeyama with scale); ``scale`` (the scale of the Sim(3) fit alone, applied to the
  estimate's positions about its origin, as evo's ``-s`` without ``-a``). ``align_first``
  N fits the Umeyama alignments to the first N paired poses only (evo's ``--n_to_align``).
- APE (evo_ape): per pose, the translation error [m] and the rotation angle [deg] of
  inv(est) gt, after the alignment.
- RPE (evo_rpe): per pair (i, j), the translation error [m] and the rotation angle [deg] of
  inv(inv(gt_i) gt_j) inv(est_i) est_j, after the alignment. Pairs: every ``delta`` frames,
  or every ``delta`` metres of path (consecutive pairs: a new pair starts where the last one
  ended, once the path since reaches ``delta``); with ``all_pairs``, from every frame (frames:
  i + delta; metres: the frame whose path distance from i is nearest ``delta``, kept within
  10 % of it). The path is the aligned estimate's (evo's default) or the ground truth's.
APE and RPE give rmse, mean, median, std, min and max, as evo does.

Inputs: a sequence MCAP (its ground truth), a trajectory Parquet (``adaptune run``) or a pose
file of any format pipeline.posefile reads. Stamped poses on both sides are paired as
evo.core.sync does: every pose of the side with fewer poses takes the nearest stamp of the
other within 10 ms (the earlier one on a tie); otherwise pose k pairs with pose k.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.geometry import inv_se3, path_distances
from pipeline.metrics.rte import per_frame_rte
from pipeline.posefile import PoseFormat, read_pose_file

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
Alignment = Literal["none", "origin", "se3", "sim3", "scale"]
ALIGNMENTS: tuple[Alignment, ...] = ("none", "origin", "se3", "sim3", "scale")
FITTED: tuple[Alignment, ...] = ("se3", "sim3", "scale")
"""The alignments fitted by Umeyama, which ``align_first`` restricts to the first poses."""
MIN_ALIGN_POSES = 3
"""Umeyama needs 3 poses at least (evo refuses fewer: a degenerate covariance)."""
DeltaUnit = Literal["frames", "m"]
MAX_STAMP_DIFF_NS = 10_000_000
"""Stamped poses pair with the nearest stamp within 10 ms (evo's max_diff 0.01 s)."""
REL_DELTA_TOL = 0.1
"""RPE over all pairs with a delta in metres: a pair is kept when its path distance is within
10 % of the delta (evo's rel_delta_tol)."""


@dataclass(frozen=True)
class Poses:
    """(N, 4, 4) poses and their (N,) stamps [ns] where the source has them; a trajectory
    Parquet's frame numbers (``frames``); ``sequence``: the poses are a sequence MCAP's, one
    per frame; ``length_m``: that sequence's own RTE length (``SequenceInfo.length_m``)."""

    what: str
    T: F64
    stamps_ns: NDArray[np.int64] | None
    frames: NDArray[np.int32] | None = None
    sequence: bool = False
    length_m: float | None = None


@dataclass(frozen=True)
class RpeSettings:
    """Which pairs the RPE compares (module docstring): ``delta`` frames (a whole number) or
    metres, consecutive pairs or ``all_pairs``, along the path of the aligned estimate or,
    with ``pairs_from_reference``, of the ground truth."""

    delta: float = 1.0
    unit: DeltaUnit = "frames"
    all_pairs: bool = False
    pairs_from_reference: bool = False

    def __post_init__(self) -> None:
        if not self.delta > 0:
            raise InputError(f"the RPE delta must be > 0, got {self.delta:g} {self.unit}")
        if self.unit == "frames" and float(self.delta) != int(self.delta):
            raise InputError(f"the RPE delta in frames must be a whole number, got "
                             f"{self.delta:g}")

    def describe(self) -> str:
        """``1 frame, consecutive pairs``."""
        unit = ("frame" if self.delta == 1 else "frames") if self.unit == "frames" else "m"
        pairs = "all pairs" if self.all_pairs else "consecutive pairs"
        return f"{self.delta:g} {unit}, {pairs}"


def load_poses(path: str | Path, fmt: PoseFormat = "auto") -> Poses:
    """The poses of a sequence MCAP (ground truth), a trajectory Parquet or a pose file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        from pipeline.sequence import SequenceReader

        with SequenceReader(path) as reader:
            gt = reader.require_ground_truth("to compare with")
            return Poses(str(path), gt, reader.stamps_ns.copy(), sequence=True,
                         length_m=reader.info.length_m)
    if suffix == ".parquet":
        from pipeline.trajectory import read_trajectory

        traj = read_trajectory(path)
        return Poses(str(path), traj.T_world_lidar, traj.stamps_ns, traj.frames)
    pf = read_pose_file(path, fmt)
    return Poses(str(path), pf.T_world_x, pf.stamps_ns)


def associate(gt: Poses, est: Poses) -> tuple[F64, F64]:
    """Paired (M, 4, 4) ground-truth and estimated poses (module docstring: evo's rule). A
    trajectory Parquet against a sequence MCAP: its frames must be the sequence's
    (``pipeline.trajectory.check_frames_of``, as `export` checks them)."""
    from pipeline.trajectory import check_frames_of

    for traj, seq in ((est, gt), (gt, est)):
        if traj.frames is not None and seq.sequence and seq.stamps_ns is not None:
            check_frames_of(traj.frames, traj.stamps_ns, seq.stamps_ns,  # type: ignore[arg-type]
                            traj.what, seq.what)
    if gt.stamps_ns is None or est.stamps_ns is None:
        if len(gt.T) != len(est.T):
            raise InputError(f"{est.what}: {len(est.T)} poses, the ground truth {gt.what} has "
                             f"{len(gt.T)} (without stamps on both sides, pose k pairs with "
                             "pose k)")
        return gt.T, est.T
    est_shorter = len(est.T) <= len(gt.T)  # evo: the side with fewer poses keeps them all
    short, long = (est, gt) if est_shorter else (gt, est)
    i_short, i_long = nearest_stamps(short.stamps_ns, long.stamps_ns)  # type: ignore[arg-type]
    if len(i_short) < 2:
        raise InputError(f"{est.what}: fewer than 2 poses within 10 ms of a ground-truth stamp "
                         f"in {gt.what}")
    if est_shorter:
        return gt.T[i_long], est.T[i_short]
    return gt.T[i_short], est.T[i_long]


def nearest_stamps(short_ns: I64, long_ns: I64) -> tuple[I64, I64]:
    """(i_short, i_long): every stamp of ``short_ns`` that has one of the increasing
    ``long_ns`` within 10 ms, and the index of the nearest such one (the earlier on a tie),
    as evo.core.sync.matching_time_indices."""
    last = len(long_ns) - 1
    upper = np.minimum(np.searchsorted(long_ns, short_ns, side="right"), last)
    lower = np.maximum(upper - 1, 0)
    d_upper = np.abs(long_ns[upper] - short_ns)
    d_lower = np.where(upper > 0, np.abs(short_ns - long_ns[lower]), np.iinfo(np.int64).max)
    nearest = np.where(d_upper < d_lower, upper, lower)
    ok = np.minimum(d_upper, d_lower) <= MAX_STAMP_DIFF_NS
    return np.flatnonzero(ok).astype(np.int64), nearest[ok].astype(np.int64)


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


def align(gt: F64, est: F64, alignment: Alignment,
          align_first: int | None = None) -> tuple[F64, float]:
    """(``est`` aligned to ``gt`` (M, 4, 4), the scale applied) for paired (M, 4, 4) poses;
    a Umeyama alignment fitted to the first ``align_first`` pairs only when given."""
    check_align_first(alignment, align_first, len(est))
    if alignment == "none":
        return est, 1.0
    if alignment == "origin":
        return gt[0] @ inv_se3(est[:1]) @ est, 1.0
    n = len(est) if align_first is None else align_first
    R, t, s = umeyama(est[:n, :3, 3], gt[:n, :3, 3], scale=alignment in ("sim3", "scale"))
    aligned = est.copy()
    if alignment == "scale":
        aligned[:, :3, 3] = s * est[:, :3, 3]
        return aligned, s
    aligned[:, :3, :3] = R @ est[:, :3, :3]
    aligned[:, :3, 3] = s * est[:, :3, 3] @ R.T + t
    return aligned, s


def check_align_first(alignment: Alignment, align_first: int | None, poses: int) -> None:
    """InputError unless ``align_first`` (None: every pose) suits ``alignment`` and the
    ``poses`` paired poses."""
    if align_first is None:
        return
    if alignment not in FITTED:
        raise InputError(f"--align-first fits a Umeyama alignment ({', '.join(FITTED)}), "
                         f"got --align {alignment}")
    if not MIN_ALIGN_POSES <= align_first <= poses:
        raise InputError(f"--align-first must be in [{MIN_ALIGN_POSES}, {poses}] (the paired "
                         f"poses), got {align_first}")


def rotation_angle_deg(R: F64) -> F64:
    """(M,) angle [deg] of (M, 3, 3) rotations: the norm of their rotation vectors (evo's
    so3_log_angle; exact for small angles, unlike the arccos of the trace)."""
    from scipy.spatial.transform import Rotation

    return np.degrees(Rotation.from_matrix(R).magnitude())


def ape_errors(gt: F64, aligned: F64) -> tuple[F64, F64]:
    """APE of paired (M, 4, 4) poses: (translation error [m], rotation angle [deg]), each
    (M,)."""
    t_err = np.linalg.norm(aligned[:, :3, 3] - gt[:, :3, 3], axis=1)
    E = inv_se3(aligned) @ gt
    return t_err, rotation_angle_deg(E[:, :3, :3])


def rpe_pairs(poses: F64, settings: RpeSettings) -> tuple[I64, I64]:
    """(i, j) index pairs (P,) of the RPE along the path of (M, 4, 4) ``poses`` (module
    docstring); InputError when there is none."""
    n = len(poses)
    if settings.unit == "frames":
        d = int(settings.delta)
        first = np.arange(0, n - d) if settings.all_pairs else np.arange(0, n, d)[:-1]
        i, j = first, first + d
    elif settings.all_pairs:
        i, j = _all_pairs_by_path(path_distances(poses), settings.delta)
    else:
        i, j = _consecutive_pairs_by_path(poses, settings.delta)
    if not len(i):
        raise InputError(f"no RPE pair of {settings.describe()} in {n} poses: try a smaller "
                         "delta")
    return i.astype(np.int64), j.astype(np.int64)


def _all_pairs_by_path(dist_m: F64, delta_m: float) -> tuple[I64, I64]:
    """From every frame i, the later frame j whose path distance from i is nearest
    ``delta_m`` (the first of equals), kept when within REL_DELTA_TOL of it."""
    i_out, j_out = [], []
    for i in range(len(dist_m) - 1):
        gap = np.abs(dist_m[i + 1:] - dist_m[i] - delta_m)
        k = int(np.argmin(gap))
        if gap[k] <= delta_m * REL_DELTA_TOL:
            i_out.append(i)
            j_out.append(i + 1 + k)
    return np.array(i_out, np.int64), np.array(j_out, np.int64)


def _consecutive_pairs_by_path(poses: F64, delta_m: float) -> tuple[I64, I64]:
    """Pairs that follow each other along the path: a pair ends at the first frame where the
    path since its start reaches ``delta_m``, and the next one starts there."""
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    ends = [0]
    since = 0.0
    for k, step in enumerate(steps, start=1):
        since += float(step)
        if since >= delta_m:
            ends.append(k)
            since = 0.0
    return np.array(ends[:-1], np.int64), np.array(ends[1:], np.int64)


def rpe_error_poses(gt: F64, aligned: F64, i: I64, j: I64) -> F64:
    """(P, 4, 4) relative pose errors inv(inv(gt_i) gt_j) inv(est_i) est_j of the pairs
    (i, j) of paired (M, 4, 4) poses."""
    d_gt = inv_se3(gt[i]) @ gt[j]
    d_est = inv_se3(aligned[i]) @ aligned[j]
    return inv_se3(d_gt) @ d_est


def pose_error_sizes(E: F64) -> tuple[F64, F64]:
    """(translation [m], rotation angle [deg]), each (P,), of (P, 4, 4) pose errors."""
    return np.linalg.norm(E[:, :3, 3], axis=1), rotation_angle_deg(E[:, :3, :3])


def rpe_errors(gt: F64, aligned: F64, i: I64, j: I64) -> tuple[F64, F64]:
    """RPE of the pairs (i, j) of paired (M, 4, 4) poses: (translation error [m], rotation
    angle [deg]), each (P,)."""
    return pose_error_sizes(rpe_error_poses(gt, aligned, i, j))


def _stats(err: F64) -> dict[str, float]:
    return {"rmse": float(np.sqrt(np.mean(err**2))), "mean": float(err.mean()),
            "median": float(np.median(err)), "std": float(err.std()),
            "min": float(err.min()), "max": float(err.max())}


@dataclass(frozen=True)
class Comparison:
    """One estimate against the ground truth: the JSON-ready ``summary`` and the per-pose
    arrays behind it (M paired poses): ``gt`` and ``aligned`` (M, 4, 4), ``path_m`` (M,)
    the ground truth's path distance [m], ``ape_t_m`` (M,) the APE translation error [m],
    ``rte_t_pct`` (M,) the translational RTE [%] of the segment starting there (NaN: none)."""

    summary: dict[str, Any]
    gt: F64
    aligned: F64
    path_m: F64
    ape_t_m: F64
    rte_t_pct: F64


def compare(gt: F64, est: F64, length_m: float, alignment: Alignment = "se3",
            rpe: RpeSettings | None = None, align_first: int | None = None) -> Comparison:
    """RTE over ``length_m`` (of ``est`` as given), then APE and RPE after ``alignment`` (fitted
    to the first ``align_first`` poses when given), of paired (M, 4, 4) poses."""
    rpe = rpe or RpeSettings()
    path = path_distances(gt)
    if path[-1] <= length_m:
        raise InputError(f"the ground truth runs {path[-1]:.2f} m, not longer than "
                         f"--length {length_m:g} m: no sub-trajectory to score")
    t_err, r_err = per_frame_rte(gt, est, length_m)
    ok = np.isfinite(t_err)
    aligned, scale = align(gt, est, alignment, align_first)
    ape_t, ape_r = ape_errors(gt, aligned)
    i, j = rpe_pairs(gt if rpe.pairs_from_reference else aligned, rpe)
    rpe_t, rpe_r = rpe_errors(gt, aligned, i, j)
    summary = {
        "frames": len(gt), "path_m": float(path[-1]),
        "rte": {"length_m": float(length_m), "segments": int(ok.sum()),
                "t_err_pct": float(t_err[ok].mean()),
                "r_err_deg_per_m": float(np.degrees(r_err[ok].mean())),
                "t_err_pct_median": float(np.median(t_err[ok])),
                "t_err_pct_max": float(t_err[ok].max())},
        "alignment": {"method": alignment, "scale": scale,
                      "poses": len(gt) if align_first is None else align_first},
        "ape": {"translation_m": _stats(ape_t), "rotation_deg": _stats(ape_r)},
        "rpe": {"delta": rpe.delta, "delta_unit": rpe.unit, "all_pairs": rpe.all_pairs,
                "pairs_from": "ground truth" if rpe.pairs_from_reference else "estimate",
                "pairs": len(i), "translation_m": _stats(rpe_t), "rotation_deg": _stats(rpe_r)},
    }
    return Comparison(summary, gt, aligned, path, ape_t, t_err)


def compare_files(gt_path: str | Path, est_paths: Sequence[str | Path],
                  length_m: float | None, alignment: Alignment = "se3",
                  rpe: RpeSettings | None = None, gt_format: PoseFormat = "auto",
                  est_format: PoseFormat = "auto",
                  align_first: int | None = None) -> tuple[Poses, list[Comparison]]:
    """(the ground truth, ``compare`` of each estimate against it) for files (module
    docstring: which files); every summary names its ground truth and estimate. The RTE's
    ``length_m``: as given (``--length``), else the ground truth's own, a sequence MCAP's
    (``SequenceInfo.length_m``); InputError with neither."""
    if length_m is not None and not length_m > 0:
        raise InputError(f"--length must be > 0 m, got {length_m}")
    truth = load_poses(gt_path, gt_format)
    if length_m is None:
        if truth.length_m is None:
            raise InputError(f"{gt_path}: no RTE length of its own (only a sequence MCAP "
                             "ingested with one has it): give --length")
        length_m = truth.length_m
    out = []
    for est_path in est_paths:
        gt, est = associate(truth, load_poses(est_path, est_format))
        if not (np.isfinite(gt).all() and np.isfinite(est).all()):
            raise InputError(f"{est_path}: a pose is not finite")
        c = compare(gt, est, length_m, alignment, rpe, align_first)
        named = {"ground_truth": str(gt_path), "estimate": str(est_path), **c.summary}
        out.append(replace(c, summary=named))
    return truth, out
