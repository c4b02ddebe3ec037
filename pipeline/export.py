"""Exported trajectories for evo and the KITTI devkit: which frame they are in, where they start.

An estimate (``T_world_lidar``, N x 4 x 4) starts at the identity, the ground truth wherever the
data set puts it. By default an export is anchored at the ground truth of its first frame,
``T_gt[k0] @ inv(T_est[0]) @ T_est`` (so ``evo_ape`` without alignment compares like with like);
``anchor="identity"`` keeps the poses as the odometry gave them.

``frame="kitti-camera"`` writes KITTI's camera-0 convention, ``T_cam_lidar @ T @ inv(T_cam_lidar)``,
the inverse of what the KITTI reader does at ingest (``inv(Tr) @ P @ Tr``), so an anchored KITTI
export lines up with ``poses/NN.txt``. ``T_cam_lidar`` (KITTI's ``Tr``) comes from the sequence's
metadata (``x.T_cam_lidar``, written by the KITTI reader) or from a calib.txt the user gives.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.geometry import inv_se3
from pipeline.io_utils import refuse_input_as_output
from pipeline.posefile import write_kitti_poses, write_tum

F64 = NDArray[np.float64]
ExportFormat = Literal["kitti", "tum"]
ExportFrame = Literal["lidar", "kitti-camera"]
Anchor = Literal["ground-truth", "identity"]
EXPORT_FORMATS = ("kitti", "tum")
EXPORT_FRAMES = ("lidar", "kitti-camera")
ANCHORS = ("ground-truth", "identity")
CALIB_KEY = "T_cam_lidar"
"""Sequence metadata key (``SequenceInfo.extra``): KITTI's Tr, 16 numbers row-major (JSON)."""


def anchor_at(T_est: F64, T_gt_first: F64) -> F64:
    """(N, 4, 4) estimate moved rigidly so that its first pose is ``T_gt_first`` (4, 4)."""
    return T_gt_first @ inv_se3(T_est[0]) @ T_est


def lidar_to_camera(T_world_lidar: F64, T_cam_lidar: F64) -> F64:
    """(N, 4, 4) lidar poses in KITTI's camera-0 convention: ``Tr @ T @ inv(Tr)``."""
    return T_cam_lidar @ T_world_lidar @ inv_se3(T_cam_lidar)


def export_trajectory(traj_path: str | Path, fmt: str, out: str | Path, *,
                      sequence: str | Path | None = None, anchor: str = "ground-truth",
                      frame: str = "lidar", calib: str | Path | None = None) -> int:
    """Write a trajectory Parquet file as KITTI or TUM text; returns the number of poses.

    ``sequence``: the sequence MCAP (ground truth, calibration); default: the one named in the
    trajectory's metadata. TUM stamps are stamp_ns / 1e9 [s].
    """
    from pipeline.trajectory import read_trajectory

    _check_choices(fmt, anchor, frame)
    traj = read_trajectory(traj_path)
    if not traj.is_finite():
        raise InputError(f"{traj_path}: trajectory has non-finite poses")
    T = traj.T_world_lidar
    needs_sequence = anchor == "ground-truth" or (frame == "kitti-camera" and calib is None)
    seq = _sequence_of(traj_path, sequence) if needs_sequence else None
    refuse_input_as_output(out, [traj_path, seq, calib])
    if anchor == "ground-truth":
        T = anchor_at(T, _first_ground_truth(seq, traj.frames, traj.stamps_ns,  # type: ignore[arg-type]
                                            traj_path))
    if frame == "kitti-camera":
        T = lidar_to_camera(T, calibration(seq, calib))
    _write(out, fmt, traj.stamps_ns, T)
    return len(T)


def export_ground_truth(sequence: str | Path, fmt: str, out: str | Path, *,
                        frame: str = "lidar", calib: str | Path | None = None) -> int:
    """Write the ground truth of a sequence MCAP as KITTI or TUM text; returns the poses."""
    from pipeline.sequence import SequenceReader

    _check_choices(fmt, "identity", frame)
    refuse_input_as_output(out, [sequence, calib])
    with SequenceReader(sequence) as reader:
        gt = reader.require_ground_truth("to export")
        stamps = np.asarray(reader.stamps_ns, dtype=np.int64)
    if frame == "kitti-camera":
        gt = lidar_to_camera(gt, calibration(Path(sequence), calib))
    _write(out, fmt, stamps, gt)
    return len(gt)


def calibration(sequence: Path | None, calib: str | Path | None) -> F64:
    """(4, 4) T_cam_lidar from ``calib`` (a KITTI calib.txt) or the sequence's metadata."""
    if calib is not None:
        from pipeline.kitti_calib import read_kitti_calib

        return read_kitti_calib(calib)
    from pipeline.sequence import SequenceReader

    with SequenceReader(sequence) as reader:  # type: ignore[arg-type]
        text = reader.info.extra.get(CALIB_KEY)
    if text is None:
        raise ConfigError(f"{sequence}: no camera calibration in the sequence (not a KITTI "
                          f"ingest); give --calib calib.txt for the kitti-camera frame")
    try:
        T = np.asarray(json.loads(text), dtype=np.float64).reshape(4, 4)
    except (ValueError, TypeError):
        raise InputError(f"{sequence}: malformed '{CALIB_KEY}' metadata") from None
    if not np.isfinite(T).all():
        raise InputError(f"{sequence}: malformed '{CALIB_KEY}' metadata")
    return T


def _sequence_of(traj_path: str | Path, sequence: str | Path | None) -> Path:
    if sequence is not None:
        return Path(sequence)
    import pyarrow.parquet as pq

    meta = pq.read_schema(traj_path).metadata or {}
    named = meta.get(b"adaptune.sequence")
    # runs, trials and adaptive runs store a path relative to the trajectory's folder (older
    # `adaptune run` files an absolute one, and older files yet the path as given, relative to
    # the working directory then): tried from the trajectory's folder, then from here
    found = [p for p in ([Path(traj_path).parent / named.decode(), Path(named.decode())]
                         if named is not None else []) if p.is_file()]
    if not found:
        raise ConfigError(f"{traj_path}: its sequence is unknown or gone; give --sequence "
                          f"SEQ.mcap (its ground truth anchors the export), or --anchor identity")
    return found[0]


def _first_ground_truth(sequence: Path, frames: NDArray[np.int32],
                        stamps_ns: NDArray[np.int64], what: str | Path) -> F64:
    """The ground-truth pose of the trajectory's (``what``) first frame; InputError unless
    each of its frames is one of the sequence (``check_frames_of``)."""
    from pipeline.sequence import SequenceReader
    from pipeline.trajectory import check_frames_of

    with SequenceReader(sequence) as reader:
        gt = reader.require_ground_truth("to anchor at; use --anchor identity")
        seq_stamps = np.asarray(reader.stamps_ns, dtype=np.int64)
    check_frames_of(frames, stamps_ns, seq_stamps, what, sequence)
    return gt[int(frames[0])]


def _check_choices(fmt: str, anchor: str, frame: str) -> None:
    for value, known, what in ((fmt, EXPORT_FORMATS, "export format"),
                               (anchor, ANCHORS, "anchor"), (frame, EXPORT_FRAMES, "frame")):
        if value not in known:
            raise ConfigError(f"unknown {what} '{value}', known: {list(known)}")


def _write(out: str | Path, fmt: str, stamps_ns: NDArray[np.int64], T: F64) -> None:
    if fmt == "kitti":
        write_kitti_poses(out, T)
    else:
        write_tum(out, stamps_ns.astype(np.float64) / 1e9, T)
