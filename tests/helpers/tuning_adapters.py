"""Small real adapters for the tuner tests (registered nowhere; the tuner loads them as
``helpers.tuning_adapters:<factory>``), and the sequence writer they run on.

``drift``: dead reckoning over the ground-truth motion with a parameter-controlled error: each
frame-to-frame translation is scaled by ``1 + 0.1 (bias - 0.2) + 0.05 ln(gain)`` and the heading
turns by ``0.002 (window - 4)`` rad a frame, so the RTE is a real function of the parameters
(smallest near bias=0.2, gain=1, window=4). It implements the Adapter protocol honestly on
sequences that carry ground truth.
``failing``: the same, but when ``bias > threshold`` it fails in one ``mode``: raise, exit (the
process ends at once), oom (the process is SIGKILLed, as by the OOM killer), hang (blocks every
signal, then sleeps: only a kill ends it), nan, lose (drops the last frame), jump (a 1 km step),
oom_once (SIGKILLed the first time it sees a parameter set, as by a passing memory shortage:
``marker_dir`` remembers; then it runs as ``drift``).
``fenced``: the same as ``drift``, but it raises at the first scan whose ground truth lies more
than ``fence_m`` from the origin, whole or streamed, whatever the parameters: a sequence that
goes that far fails part-way through every trial, a shorter one never.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from pipeline.geometry import inv_se3, rot_z
from pipeline.odometry.base import ParameterSpace, ParamSpec, Schedule
from pipeline.sequence import Scan, SequenceInfo, SequenceWriter
from pipeline.trajectory import Trajectory

SPACE = ParameterSpace(
    (
        ParamSpec("bias", -1.0, 1.0, 0.5),
        ParamSpec("gain", 0.25, 4.0, 1.0, log=True),
        ParamSpec("window", 1, 6, 3, kind="int"),
    )
)


class DriftAdapter:
    """Dead reckoning on the ground-truth motion with a parameter-controlled drift.

    Streams too (``start``) once ``warm`` has seen the scans: it then finds each scan's ground
    truth by its stamp (an odometry step gets points and a stamp only).
    """

    name = "drift"
    space = SPACE

    def __init__(self) -> None:
        self.truth: dict[int, np.ndarray] = {}

    def warm(self, scans: list[Scan]) -> None:
        self.truth = {s.stamp_ns: s.T_world_lidar for s in scans if s.T_world_lidar is not None}

    def start(self, params: dict[str, float]) -> DriftOdometry:
        return DriftOdometry(self, self.space.validate(params))

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        frames, stamps, poses = [], [], []
        T = np.eye(4)
        prev = None
        for i, scan in enumerate(scans):
            if scan.T_world_lidar is None:
                raise ValueError("drift needs ground truth")
            if prev is not None:
                T = T @ self.step(inv_se3(prev) @ scan.T_world_lidar, schedule.at(i))
            prev = scan.T_world_lidar
            frames.append(scan.frame)
            stamps.append(scan.stamp_ns)
            poses.append(T.copy())
        return Trajectory(np.array(frames), np.array(stamps), np.stack(poses))

    @staticmethod
    def step(dT: np.ndarray, p: dict[str, float]) -> np.ndarray:
        out = dT.copy()
        out[:3, 3] *= 1.0 + 0.1 * (p["bias"] - 0.2) + 0.05 * math.log(p["gain"])
        out[:3, :3] = rot_z(0.002 * (p["window"] - 4.0)) @ out[:3, :3]
        return out


class DriftOdometry:
    """The streaming form of DriftAdapter (same poses, bitwise)."""

    def __init__(self, adapter: DriftAdapter, params: dict[str, float]) -> None:
        self.adapter, self.params = adapter, params
        self.T = np.eye(4)
        self.prev: np.ndarray | None = None

    def set_params(self, params: dict[str, float]) -> None:
        self.params = self.adapter.space.validate(params)

    def step(self, points_lidar: np.ndarray, stamp_ns: int) -> np.ndarray:
        gt = self.adapter.truth[int(stamp_ns)]
        if self.prev is not None:
            self.T = self.T @ DriftAdapter.step(inv_se3(self.prev) @ gt, self.params)
        self.prev = gt
        return self.T.copy()


class FailingAdapter(DriftAdapter):
    """DriftAdapter that fails in ``mode`` whenever bias > ``threshold``."""

    name = "failing"

    def __init__(self, mode: str, threshold: float = 0.0, marker_dir: str = "") -> None:
        super().__init__()
        self.mode = mode
        self.threshold = threshold
        self.marker_dir = marker_dir

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        if schedule.at(0)["bias"] <= self.threshold:
            return super().run(scans, schedule)
        if self.mode == "raise":
            raise RuntimeError("odometry diverged on purpose")
        if self.mode == "exit":  # the process dies without a word (as a segfault would)
            os._exit(3)
        if self.mode == "oom":  # killed from outside, as the OOM killer does
            os.kill(os.getpid(), signal.SIGKILL)
        if self.mode == "oom_once":
            marker = Path(self.marker_dir) / repr(sorted(schedule.at(0).items()))
            if not marker.exists():
                marker.touch()
                os.kill(os.getpid(), signal.SIGKILL)
            return super().run(scans, schedule)
        if self.mode == "hang":
            signal.pthread_sigmask(signal.SIG_BLOCK, set(signal.valid_signals()) - {signal.SIGKILL})
            while True:
                time.sleep(60)
        traj = super().run(scans, schedule)
        if self.mode == "nan":
            traj.T_world_lidar[3, 0, 3] = np.nan
        elif self.mode == "lose":
            return Trajectory(traj.frames[:-1], traj.stamps_ns[:-1], traj.T_world_lidar[:-1])
        elif self.mode == "jump":
            traj.T_world_lidar[5:, 0, 3] += 1000.0
        return traj


class FencedDriftAdapter(DriftAdapter):
    """DriftAdapter that raises at the first scan farther than ``fence_m`` [m] from the origin
    (by its ground truth), whole or streamed."""

    name = "fenced"

    def __init__(self, fence_m: float) -> None:
        super().__init__()
        self.fence_m = fence_m

    def check(self, T_world_lidar: np.ndarray, frame: int) -> None:
        """RuntimeError when the pose ``T_world_lidar`` lies beyond the fence."""
        if np.linalg.norm(T_world_lidar[:3, 3]) > self.fence_m:
            raise RuntimeError(f"left the {self.fence_m:g} m fence at frame {frame}")

    def start(self, params: dict[str, float]) -> DriftOdometry:
        return FencedOdometry(self, self.space.validate(params))

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        scans = list(scans)
        for scan in scans:
            if scan.T_world_lidar is not None:
                self.check(scan.T_world_lidar, scan.frame)
        return super().run(scans, schedule)


class FencedOdometry(DriftOdometry):
    """The streaming form of FencedDriftAdapter."""

    def __init__(self, adapter: FencedDriftAdapter, params: dict[str, float]) -> None:
        super().__init__(adapter, params)
        self.fence = adapter
        self.frame = 0

    def step(self, points_lidar: np.ndarray, stamp_ns: int) -> np.ndarray:
        self.fence.check(self.adapter.truth[int(stamp_ns)], self.frame)
        self.frame += 1
        return super().step(points_lidar, stamp_ns)


class SleepyDriftAdapter(DriftAdapter):
    """DriftAdapter that first sleeps 0-0.3 s, a different time for every parameter set, so
    that parallel trials finish out of order."""

    name = "sleepy"

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        p = schedule.at(0)
        time.sleep(0.3 * ((p["bias"] * 7919 + p["gain"] * 104729 + p["window"]) % 1.0))
        return super().run(scans, schedule)


class WarmLogAdapter(SleepyDriftAdapter):
    """SleepyDriftAdapter that leaves a file in ``log_dir`` every time a process warms it:
    ``<pid>-<n>.warm`` holding the warmed sequence's first stamp and last ground-truth x [m]
    (which process warmed which study)."""

    name = "warm_log"

    def __init__(self, log_dir: str) -> None:
        super().__init__()
        self.log_dir = Path(log_dir)

    def warm(self, scans: list[Scan]) -> None:
        super().warm(scans)
        n = len(list(self.log_dir.glob(f"{os.getpid()}-*.warm")))
        last = scans[-1].T_world_lidar
        x = float(last[0, 3]) if last is not None else math.nan
        (self.log_dir / f"{os.getpid()}-{n}.warm").write_text(f"{len(scans)} {x:.6f}")


def warm_log(log_dir: str) -> WarmLogAdapter:
    return WarmLogAdapter(log_dir)


def sleepy() -> SleepyDriftAdapter:
    return SleepyDriftAdapter()


def drift() -> DriftAdapter:
    return DriftAdapter()


def fenced(fence_m: float) -> FencedDriftAdapter:
    return FencedDriftAdapter(fence_m)


def failing(mode: str, threshold: float = 0.0, marker_dir: str = "") -> FailingAdapter:
    return FailingAdapter(mode, threshold, marker_dir)


def write_sequence(
    path: Path, n_frames: int = 30, step_m: float = 1.0, yaw_rate: float = 0.02, seed: int = 0,
    first_stamp_ns: int = 0,
) -> Path:
    """A small sequence MCAP: 64 random points a scan, ground truth along a gentle curve, a
    scan every 0.1 s from ``first_stamp_ns`` (the streamed drift adapter finds a scan's ground
    truth by its stamp: the sequences of a joint study it streams need stamps of their own)."""
    rng = np.random.default_rng(seed)
    with SequenceWriter(path, SequenceInfo(name=path.stem, sensor="test", source="tests")) as w:
        T = np.eye(4)
        for k in range(n_frames):
            w.add(first_stamp_ns + k * 100_000_000,
                  rng.uniform(-10, 10, (64, 4)).astype(np.float32), T.copy())
            dT = np.eye(4)
            dT[:3, :3] = rot_z(yaw_rate)
            dT[0, 3] = step_m
            T = T @ dT
    return path
