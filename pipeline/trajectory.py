"""Trajectories: T_world_lidar per frame, stored as Parquet (schemas.arrow.TRAJECTORY)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.io_utils import atomic_path, input_file
from schemas.arrow import POSE_COLUMNS, TRAJECTORY, check_schema_version


@dataclass
class Trajectory:
    """frames: (N,) int32; stamps_ns: (N,) int64; T_world_lidar: (N, 4, 4) float64 [m]."""

    frames: NDArray[np.int32]
    stamps_ns: NDArray[np.int64]
    T_world_lidar: NDArray[np.float64]

    def __post_init__(self) -> None:
        self.frames = np.asarray(self.frames, dtype=np.int32)
        self.stamps_ns = np.asarray(self.stamps_ns, dtype=np.int64)
        self.T_world_lidar = np.asarray(self.T_world_lidar, dtype=np.float64)
        n = len(self.frames)
        if self.stamps_ns.shape != (n,) or self.T_world_lidar.shape != (n, 4, 4):
            raise InputError(f"trajectory arrays disagree: frames {self.frames.shape}, stamps "
                             f"{self.stamps_ns.shape}, poses {self.T_world_lidar.shape}")

    def __len__(self) -> int:
        return len(self.frames)

    def is_finite(self) -> bool:
        """True when every pose is finite."""
        return bool(np.isfinite(self.T_world_lidar).all())

    def to_table(self) -> pa.Table:
        """Arrow table following schemas.arrow.TRAJECTORY."""
        flat = self.T_world_lidar[:, :3, :].reshape(-1, 12)
        cols = [pa.array(self.frames, pa.int32()), pa.array(self.stamps_ns, pa.int64())]
        cols += [pa.array(flat[:, i], pa.float64()) for i in range(12)]
        return pa.Table.from_arrays(cols, schema=TRAJECTORY)

    @classmethod
    def from_table(cls, table: pa.Table, what: str = "trajectory") -> Trajectory:
        """Inverse of ``to_table``; raises InputError on missing columns."""
        missing = [c for c in ("frame", "stamp_ns", *POSE_COLUMNS) if c not in table.column_names]
        if missing:
            raise InputError(f"{what}: missing trajectory columns {missing}")
        flat = np.stack([table.column(c).to_numpy() for c in POSE_COLUMNS], axis=1)
        T = np.zeros((len(flat), 4, 4))
        T[:, :3, :] = flat.reshape(-1, 3, 4)
        T[:, 3, 3] = 1.0
        return cls(table.column("frame").to_numpy(), table.column("stamp_ns").to_numpy(), T)


def check_frames_of(frames: NDArray[np.integer], stamps_ns: NDArray[np.int64],
                    sequence_stamps_ns: NDArray[np.int64], what: str | Path,
                    sequence: str | Path) -> None:
    """InputError unless every frame number of a trajectory (``what``) is a frame of
    ``sequence`` (whose frame stamps are ``sequence_stamps_ns``) at the trajectory's own stamp:
    the one check `export` (its anchor) and `metric` (its pairs) make before they use a
    trajectory against a sequence (a run of another sequence, or renumbered frames, is not
    scored or anchored)."""
    frames = np.asarray(frames, dtype=np.int64)
    n = len(sequence_stamps_ns)
    inside = (frames >= 0) & (frames < n)
    bad = ~inside
    bad[inside] = sequence_stamps_ns[frames[inside]] != np.asarray(stamps_ns)[inside]
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{sequence}: the trajectory {what}'s frame {int(frames[k])} (stamp "
                         f"{int(stamps_ns[k])} ns) is not a frame of this sequence ({n} frames, "
                         f"stamps {int(sequence_stamps_ns[0]) if n else '-'}.."
                         f"{int(sequence_stamps_ns[-1]) if n else '-'} ns)")


def write_trajectory(
    path: str | Path, traj: Trajectory, metadata: dict[str, str] | None = None
) -> None:
    """Write ``traj`` as one Parquet file, atomically; ``metadata`` goes into the file footer."""
    table = traj.to_table()
    if metadata:
        meta = dict(table.schema.metadata or {})
        meta.update({f"adaptune.{k}".encode(): str(v).encode() for k, v in metadata.items()})
        table = table.replace_schema_metadata(meta)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a trajectory Parquet file written by ``write_trajectory``; InputError unless it
    holds what adaptune writes (``check_poses``)."""
    path = input_file(path, "trajectory file")
    try:
        table = pq.read_table(path)
    except (pa.ArrowInvalid, OSError) as exc:
        raise InputError(f"{path}: not a readable Parquet file ({exc})") from exc
    check_schema_version(table.schema, str(path))
    traj = Trajectory.from_table(table, str(path))
    check_poses(traj, str(path))
    return traj


def check_poses(traj: Trajectory, what: str) -> None:
    """InputError naming the first thing in ``traj`` no odometry run gives: no poses, frame
    numbers that repeat or go back, a pose that is not finite, a rotation that is not a
    rotation (a score or an export of such poses would be a number without a meaning)."""
    from pipeline.geometry import refuse_non_rotations

    if len(traj) == 0:
        raise InputError(f"{what}: the trajectory has no poses")
    back = np.flatnonzero(np.diff(traj.frames) <= 0)
    if len(back):
        k = int(back[0]) + 1
        raise InputError(f"{what}: frame numbers must increase, row {k} has frame "
                         f"{traj.frames[k]} after frame {traj.frames[k - 1]}")
    finite = np.isfinite(traj.T_world_lidar.reshape(len(traj), -1)).all(axis=1)
    if not finite.all():
        raise InputError(f"{what}: the pose of frame {traj.frames[np.argmin(finite)]} is not "
                         "finite")
    refuse_non_rotations(traj.T_world_lidar[:, :3, :3], f"{what}: trajectory")
