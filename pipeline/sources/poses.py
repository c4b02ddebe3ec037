"""Ground truth for the scans: pose files in the LiDAR frame, time matching, a frame check.

- Pose files (every format of pipeline.posefile): without stamps pose k is scan k
  (the counts must match); stamped poses are interpolated to the scan stamps (linear in
  translation, slerp in rotation); a scan outside the poses' time span is an error.
- The extrinsic E = T_x_lidar (LiDAR -> the frame x the poses describe; KITTI's ``Tr``:
  velodyne -> camera 0) turns poses of x into LiDAR poses: T_world_lidar = inv(E) @ P @ E.
  It is given as 12 or 16 numbers, a file of them, or a KITTI calib.txt (its ``Tr`` line).
- ``warn_if_not_lidar_frame``: LiDAR frames are x forward, z up; when the ground truth moves
  mostly along the sensor's z axis the poses are likely a camera's (z forward): one warning.
- ``GroundTruthOptions``: where a source's ground truth comes from (topic, pose file,
  extrinsic), the one options type of the recording and folder sources, of ``adaptune ingest``
  and of a params.yaml ``data`` source.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pydantic import model_validator

from pipeline.config import Section
from pipeline.errors import InputError
from pipeline.geometry import (
    MAX_POSITION_M,
    interpolate_rotations,
    inv_se3,
    refuse_non_rotations,
)
from pipeline.io_utils import read_input_text
from pipeline.kitti_calib import has_kitti_calib, read_kitti_calib
from pipeline.posefile import PoseFile, PoseFormat, read_pose_file

log = logging.getLogger(__name__)

MATCH_TOLERANCE_NS = 10_000_000
"""A scan up to 10 ms outside the poses' time span takes the nearest end pose."""
MAX_GAP_NS = 1_000_000_000
"""Two poses further apart than 1 s are not interpolated between."""
Z_MOTION_SHARE = 0.7
"""Warn when more than this share of the path runs along the sensor's z axis."""


class GroundTruthOptions(Section):
    """Where a source's ground truth comes from; the keys are those of a params.yaml ``data``
    source and, with dashes, the options of ``adaptune ingest``.

    gt_topic: a PoseStamped, PoseWithCovarianceStamped, TransformStamped, Odometry or TF topic
    of a recording; None: the recording's only topic of the first four types where it has
    exactly one (``pick_ground_truth_topic``), else none. gt_child_frame: with a TF topic, the
    child frame whose pose is the ground truth. poses: a pose file (``pipeline.posefile``) in
    ``poses_format`` (auto: from its content). extrinsic: E = T_x_lidar (``read_extrinsic``),
    the LiDAR in the frame the poses describe.
    """

    gt_topic: str | None = None
    gt_child_frame: str | None = None
    poses: str | None = None
    poses_format: PoseFormat = "auto"
    extrinsic: str | None = None

    @model_validator(mode="after")
    def _one_source(self) -> GroundTruthOptions:
        if self.gt_topic is not None and self.poses is not None:
            raise ValueError(f"give either gt_topic or poses, not both, got (gt_topic="
                             f"{self.gt_topic!r}, poses={self.poses!r})")
        if self.gt_child_frame is not None and self.gt_topic is None:
            raise ValueError(f"gt_child_frame needs gt_topic (a TF topic), got (gt_topic=None, "
                             f"gt_child_frame={self.gt_child_frame!r})")
        return self

    def pose_file(self) -> PoseFile | None:
        """The pose file ``poses``, read, or None."""
        return None if self.poses is None else read_pose_file(self.poses, self.poses_format)

    def files(self) -> tuple[str, ...]:
        """The pose and extrinsic files named (an extrinsic may be numbers instead)."""
        return tuple(v for v in (self.poses, self.extrinsic) if v is not None)

    def resolved_paths(self, base_dir: Path) -> dict[str, str | None]:
        """``poses`` and ``extrinsic`` (unless it is numbers) with relative paths made absolute
        from ``base_dir``."""
        extrinsic = self.extrinsic
        if extrinsic is not None and not is_numbers(extrinsic):
            extrinsic = resolve_path(extrinsic, base_dir)
        return {"poses": resolve_path(self.poses, base_dir), "extrinsic": extrinsic}


def resolve_path(value: str | None, base_dir: Path) -> str | None:
    """``value`` as an absolute path (``~`` expanded; relative: from ``base_dir``), or None."""
    if value is None:
        return None
    path = Path(value).expanduser()
    return str(path if path.is_absolute() else base_dir / path)


def is_numbers(text: str) -> bool:
    """True when ``text`` is numbers (an extrinsic given inline), not a file name."""
    return re.fullmatch(r"[\s,0-9eE.+-]+", text) is not None


def read_extrinsic(value: str | Path) -> NDArray[np.float64]:
    """(4, 4) E = T_x_lidar from 12 or 16 numbers (row-major, space or comma separated), a file
    holding them, or a KITTI calib.txt (its ``Tr`` line)."""
    text = str(value)
    source = "--extrinsic"
    path = Path(text)
    if not is_numbers(text):
        try:
            is_file = path.is_file()
        except OSError:  # a name too long
            is_file = False
        if not is_file:
            raise InputError(f"--extrinsic {text[:80]!r} is neither 12 or 16 numbers nor a "
                             "file")
        content = read_input_text(path, "extrinsic file")
        if has_kitti_calib(content):
            return read_kitti_calib(path)
        text, source = content, str(path)
    try:
        vals = [float(v) for v in re.split(r"[\s,]+", text.strip()) if v]
    except ValueError:
        raise InputError(f"{source}: an extrinsic is 12 or 16 numbers") from None
    if len(vals) not in (12, 16) or not np.isfinite(vals).all():
        raise InputError(f"{source}: an extrinsic is 12 or 16 finite numbers (row-major 3x4 "
                         f"or 4x4), got {len(vals)}")
    E = np.eye(4)
    E[: len(vals) // 4] = np.reshape(vals, (-1, 4))
    if len(vals) == 16 and not np.allclose(E[3], [0, 0, 0, 1]):
        raise InputError(f"{source}: the last row of a 4x4 extrinsic must be 0 0 0 1")
    refuse_non_rotations(E[None, :3, :3], f"{source}: extrinsic")
    return E


def to_lidar_frame(
    T_world_x: NDArray[np.float64], E: NDArray[np.float64]
) -> NDArray[np.float64]:
    """LiDAR poses inv(E) @ P @ E of (..., 4, 4) poses P of frame x, E = T_x_lidar (KITTI:
    camera poses and Tr)."""
    return inv_se3(E) @ T_world_x @ E


def warn_if_not_lidar_frame(T_world_lidar: NDArray[np.float64], what: str) -> bool:
    """Log one warning (and return True) when the ground truth moves mostly along the sensor's
    z axis: more than Z_MOTION_SHARE of a path of 1 m or more."""
    if len(T_world_lidar) < 2:
        return False
    step = np.diff(T_world_lidar[:, :3, 3], axis=0)
    local = np.einsum("nji,nj->ni", T_world_lidar[:-1, :3, :3], step)  # R^T d: sensor frame
    path = np.linalg.norm(local, axis=1).sum()
    if path < 1.0:
        return False
    share = float(np.abs(local[:, 2]).sum() / np.abs(local).sum())
    if share <= Z_MOTION_SHARE:
        return False
    log.warning("%s: the ground truth moves mostly along the sensor's z axis (%.0f %% of the "
                "motion): camera-frame poses (z forward)? give the LiDAR extrinsic with "
                "--extrinsic or --calib", what, 100 * share)
    return True


def check_count(poses: PoseFile, n_scans: int, scans_what: str) -> None:
    """A pose file without stamps must hold exactly one pose per scan."""
    if len(poses.T_world_x) != n_scans:
        raise InputError(
            f"{poses.path}: {len(poses.T_world_x)} poses for {n_scans} scans in {scans_what}"
        )


class GroundTruth:
    """Per-scan ground truth T_world_lidar from stamped poses (interpolated) or poses without
    stamps (pose k = scan k)."""

    def __init__(
        self, what: str, stamps_ns: NDArray[np.int64] | None, T: NDArray[np.float64]
    ) -> None:
        self.what, self.stamps_ns, self.T = what, stamps_ns, T

    def at(self, frame: int, stamp: int) -> NDArray[np.float64]:
        if self.stamps_ns is None:
            return self.T[frame]
        return interpolate_poses(np.array([stamp], np.int64), self.stamps_ns, self.T, self.what)[0]

    def all_at(self, stamps_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        """(N, 4, 4) poses of the scans at ``stamps_ns`` (N,)."""
        if self.stamps_ns is None:
            return self.T[: len(stamps_ns)]
        return interpolate_poses(stamps_ns, self.stamps_ns, self.T, self.what)



def lidar_ground_truth(
    from_topic: GroundTruth | None, pose_file: PoseFile | None, extrinsic: str | Path | None,
    n_scans: int | None, scans_what: str,
) -> GroundTruth | None:
    """The ground truth of a source in the LiDAR frame: a pose file's (checked against the
    ``n_scans`` scans when it has no stamps), else a topic's; ``extrinsic``
    (``read_extrinsic``) applied, or the camera-frame warning when there is none."""
    gt = from_topic
    if pose_file is not None:
        if pose_file.stamps_ns is None and n_scans is not None:
            check_count(pose_file, n_scans, scans_what)
        far = np.abs(pose_file.T_world_x[:, :3, 3]).max(axis=1) > MAX_POSITION_M
        if far.any():
            k = int(np.flatnonzero(far)[0])
            raise InputError(f"{pose_file.path}: pose {k} is at "
                             f"{pose_file.T_world_x[k, :3, 3].tolist()} m, beyond "
                             f"{MAX_POSITION_M:g} m: not a trajectory on Earth")
        gt = GroundTruth(str(pose_file.path), pose_file.stamps_ns, pose_file.T_world_x)
    if extrinsic is not None:
        E = read_extrinsic(extrinsic)
        if gt is None:
            raise InputError(f"{scans_what}: --extrinsic without a ground truth to apply it to")
        return GroundTruth(gt.what, gt.stamps_ns, to_lidar_frame(gt.T, E))
    if gt is not None:
        warn_if_not_lidar_frame(gt.T, gt.what)
    return gt


def interpolate_poses(
    query_ns: NDArray[np.int64],
    stamps_ns: NDArray[np.int64],
    T_world_x: NDArray[np.float64],
    what: str,
) -> NDArray[np.float64]:
    """(Q, 4, 4) poses at ``query_ns`` from stamped poses (M, 4, 4) (sorted by ``stamps_ns``).

    Linear in translation, slerp in rotation; exact where a stamp matches. Raises InputError
    (naming ``what``) for a query outside the span (beyond MATCH_TOLERANCE_NS) or between
    two poses more than MAX_GAP_NS apart.
    """
    order = np.argsort(stamps_ns, kind="stable")
    t = np.asarray(stamps_ns, np.int64)[order]
    T = np.asarray(T_world_x, np.float64)[order]
    q = np.asarray(query_ns, np.int64)
    outside = (q < t[0] - MATCH_TOLERANCE_NS) | (q > t[-1] + MATCH_TOLERANCE_NS)
    if outside.any():
        which = (
            f"the scan at {q[0] / 1e9:.3f} s lies"
            if len(q) == 1
            else f"{int(outside.sum())} of {len(q)} scans (first at "
            f"{q[outside][0] / 1e9:.3f} s) lie"
        )
        raise InputError(
            f"{what}: {which} outside the ground-truth time span "
            f"[{t[0] / 1e9:.3f}, {t[-1] / 1e9:.3f}] s"
        )
    qc = np.clip(q, t[0], t[-1])
    hi = np.clip(np.searchsorted(t, qc, side="left"), 0, len(t) - 1)
    lo = np.clip(hi - 1, 0, len(t) - 1)
    exact = t[hi] == qc
    lo = np.where(exact, hi, lo)
    gap = t[hi] - t[lo]
    if np.any(gap > MAX_GAP_NS):
        k = int(np.flatnonzero(gap > MAX_GAP_NS)[0])
        raise InputError(
            f"{what}: no ground-truth pose within {MAX_GAP_NS / 1e9:g} s around "
            f"the scan at {q[k] / 1e9:.3f} s"
        )
    alpha = np.where(gap > 0, (qc - t[lo]) / np.maximum(gap, 1), 0.0)
    out = np.tile(np.eye(4), (len(q), 1, 1))
    out[:, :3, 3] = (1 - alpha)[:, None] * T[lo, :3, 3] + alpha[:, None] * T[hi, :3, 3]
    out[:, :3, :3] = interpolate_rotations(
        (qc - t[0]).astype(np.float64), (t - t[0]).astype(np.float64), T[:, :3, :3]
    )
    out[exact] = T[hi[exact]]
    return out
