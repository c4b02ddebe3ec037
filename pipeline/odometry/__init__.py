"""Odometry: the black-box contract (``base``), the adapter registry and ``run_sequence``.

``run_sequence(adapter, sequence_path, params_or_schedule, time_limit_s)`` is what the tuner,
``adaptune run`` and the adaptive stage call: it reads a sequence MCAP, validates the
parameters, runs the adapter and checks its trajectory. Estimated poses are relative to the
first frame (T_world_lidar[0] = identity); compare them with ground truth through relative
errors (RTE) or after aligning the first pose.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError, OdometryError, TrialTimeout
from pipeline.io_utils import prefetch
from pipeline.odometry.base import Adapter, Schedule, TimeLimitedAdapter
from pipeline.odometry.registry import adapter_names, get_adapter
from pipeline.progress import progress
from pipeline.sequence import Scan, SequenceReader
from pipeline.trajectory import Trajectory

__all__ = ["adapter_names", "check_trajectory", "get_adapter", "make_schedule", "run_scans",
           "run_sequence"]


def run_sequence(adapter: Adapter, sequence_path: str | Path,
                 params_or_schedule: Mapping[str, float] | Schedule,
                 time_limit_s: float | None = None, show_progress: bool = False) -> Trajectory:
    """Run ``adapter`` over the sequence MCAP at ``sequence_path``; a checked Trajectory.

    ``params_or_schedule``: fixed parameters (validated; missing ones take the baseline) or a
    per-frame Schedule (validated against the adapter's space and the frame count).
    ``time_limit_s``: in-process adapters are checked between frames (a soft limit, TrialTimeout);
    adapters with ``accepts_time_limit`` (``command``) enforce it themselves.
    ``show_progress``: a bar or log lines over the frames (``pipeline.progress``; in-process
    adapters: an external command's frames are its own).
    Raises ConfigError / InputError for bad parameters or input, OdometryError for a failed run.
    """
    path = Path(sequence_path)
    if time_limit_s is not None and not time_limit_s > 0:  # NaN too
        raise ConfigError(f"time limit must be a number of seconds > 0, got {time_limit_s}")
    with SequenceReader(path) as reader:
        schedule = make_schedule(adapter, params_or_schedule, len(reader), str(path))
        if isinstance(adapter, TimeLimitedAdapter) and adapter.accepts_time_limit:
            traj = adapter.run(reader, schedule, time_limit_s=time_limit_s)
        else:
            with contextlib.closing(prefetch(reader)) as ahead:  # decoding overlaps odometry
                scans: Iterable[Scan] = progress(ahead, len(reader), f"{adapter.name} on "
                                                 f"{reader.info.name}", enabled=show_progress)
                if time_limit_s is not None:
                    scans = _with_deadline(scans, time_limit_s, adapter.name)
                traj = _run_adapter(adapter, scans, schedule, str(path))
        check_trajectory(traj, reader.stamps_ns, f"{adapter.name} on {path}")
    return traj


def run_scans(adapter: Adapter, scans: list[Scan], stamps_ns: np.ndarray,
              params_or_schedule: Mapping[str, float] | Schedule, what: str) -> Trajectory:
    """``run_sequence`` over scans already decoded (``stamps_ns`` (N,) theirs; ``what`` names
    them in errors): a checked Trajectory, OdometryError for a failed run."""
    schedule = make_schedule(adapter, params_or_schedule, len(scans), what)
    traj = _run_adapter(adapter, scans, schedule, what)
    check_trajectory(traj, stamps_ns, f"{adapter.name} on {what}")
    return traj


def _run_adapter(adapter: Adapter, scans: Iterable[Scan], schedule: Schedule,
                 what: str) -> Trajectory:
    """``adapter.run``, the numeric failures of an odometry as OdometryError."""
    try:
        return adapter.run(scans, schedule)
    except (OdometryError, TrialTimeout):
        raise
    except (ArithmeticError, ValueError, np.linalg.LinAlgError, RuntimeError) as exc:
        raise OdometryError(f"{adapter.name} on {what}: failed "
                            f"({type(exc).__name__}: {exc})") from exc


def make_schedule(adapter: Adapter, params_or_schedule: Mapping[str, float] | Schedule,
                  n_frames: int, what: str = "schedule") -> Schedule:
    """A validated Schedule of ``n_frames`` frames: constant for fixed parameters."""
    if isinstance(params_or_schedule, Schedule):
        params_or_schedule.validate(adapter.space, n_frames, what)
        return params_or_schedule
    params = adapter.space.validate(params_or_schedule)
    return Schedule.constant(params, n_frames)


def check_trajectory(traj: Trajectory, stamps_ns: np.ndarray, what: str) -> None:
    """OdometryError unless ``traj`` has one finite rigid pose per frame 0..N-1 at ``stamps_ns``."""
    n = len(stamps_ns)
    if len(traj) != n:
        raise OdometryError(f"{what}: returned {len(traj)} poses for {n} frames")
    if not np.array_equal(traj.frames, np.arange(n)):
        raise OdometryError(f"{what}: frames are not 0..{n - 1} in order")
    if not np.array_equal(traj.stamps_ns, np.asarray(stamps_ns, np.int64)):
        k = int(np.argmax(traj.stamps_ns != stamps_ns))
        raise OdometryError(f"{what}: stamp of frame {k} is {traj.stamps_ns[k]} ns, "
                            f"the sequence says {stamps_ns[k]} ns")
    T = traj.T_world_lidar
    finite = np.isfinite(T.reshape(n, -1)).all(axis=1)
    if not finite.all():
        raise OdometryError(f"{what}: non-finite pose at frame {int(np.argmin(finite))}")
    R = T[:, :3, :3]
    ortho = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    bottom = np.abs(T[:, 3, :] - [0, 0, 0, 1]).max(axis=1)
    bad = (ortho > 1e-4) | (bottom > 1e-9)
    if bad.any():
        raise OdometryError(f"{what}: pose of frame {int(np.argmax(bad))} is not a rigid transform")


def _with_deadline(scans: Iterable[Scan], time_limit_s: float, name: str) -> Iterator[Scan]:
    """``scans``, raising TrialTimeout between frames once ``time_limit_s`` has passed."""
    deadline = time.monotonic() + time_limit_s
    for scan in scans:
        if time.monotonic() > deadline:
            raise TrialTimeout(f"{name}: time limit of {time_limit_s:g} s exceeded "
                               f"at frame {scan.frame}")
        yield scan
