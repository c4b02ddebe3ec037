"""One subject of a suite held in memory, on which every setting runs (``LoadedWorld``).

A subject (a simulated world or a recorded run, ``studies.suites.worlds``) is run many times:
baseline, fixed and adaptive, each on the nominal parameters and on every replica, and the
headroom study's candidates. Loading it and down-sampling its scans (``Adapter.warm``) cost
more than an NDT run on them, so they happen once: a world's scans are simulated straight into
memory (``pipeline.sim.simulate.simulate_scans``: no MCAP is written, compressed and decoded
again for a world that is thrown away; a 1200-frame HDL-64E world takes about 2.4 GB) and every
run goes over them.

A run on replica r (``pipeline.evaluate.replicas``: r = 0 the nominal parameters, r >= 1 every
parameter times the factor drawn from (the subject's name, r), the adaptive schedule scaled as
a whole) gives the per-start-frame RTE (N,) [%] at L; a run whose odometry fails scores the
failure penalty on every sub-trajectory (``penalty_pct``, the trials' penalty), so a failure
counts in the subject's median over runs, in the pooled RTE and in the failure rate; without a
penalty (None: the toy's generalization suite) a failed run has no score (NaN), as a failed
replica of the evaluate stage.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError, OdometryError
from pipeline.odometry.base import Schedule
from pipeline.selection import SelectionSettings
from pipeline.sequence import Scan

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Selection:
    """An adaptive schedule and what the selector did: parameter changes, the share of its
    selections that fell back on an unfamiliar scan (``novel_share``) and the share of frames
    run with a parameter within 1 % of its range's bound (``edge_share``)."""

    schedule: Schedule
    changes: int
    novel_share: float
    edge_share: float


class LoadedWorld:
    """A world's scans held in memory with the adapter warmed over them (module docstring).

    ``scans``: every frame in order, each with its ground-truth pose; ``labels``: each frame's
    environment label. ``stamps_ns`` and ``__getitem__`` make it a reader for ``Selector``."""

    def __init__(self, name: str, scans: list[Scan], labels: list[str], algorithm: str,
                 adapter_options: Mapping[str, Any] | None, space: Any, length_m: float,
                 penalty_pct: float | None, jump_limit_m: float | None = None) -> None:
        from pipeline.odometry.registry import build_adapter

        if len(labels) != len(scans):
            raise InputError(f"{name}: {len(scans)} scans, {len(labels)} labels (one a frame)")
        poses = [s.T_world_lidar for s in scans]
        missing = [s.frame for s, T in zip(scans, poses, strict=True) if T is None]
        if missing:
            raise InputError(f"{name}: frame {missing[0]} needs a ground-truth pose to score the "
                             f"suite's runs against ({len(missing)} frames have none)")
        self.name = name
        self.scans = scans
        self.labels = labels
        self.gt = np.stack([T for T in poses if T is not None])
        self.stamps_ns = np.array([s.stamp_ns for s in self.scans], np.int64)
        self.adapter = build_adapter(algorithm, adapter_options, space)
        warm = getattr(self.adapter, "warm", None)
        if warm is not None:
            warm(self.scans)
        self.length_m = length_m
        self.penalty_pct = penalty_pct
        self.jump_limit_m = jump_limit_m
        self.scored = self._scored_frames()

    def __len__(self) -> int:
        return len(self.scans)

    def __getitem__(self, frame: int) -> Any:
        return self.scans[frame]

    def _scored_frames(self) -> NDArray[np.bool_]:
        """(N,) True at the start frames that have a sub-trajectory of L metres."""
        from pipeline.metrics.rte import per_frame_rte

        t_err, _ = per_frame_rte(self.gt, self.gt, self.length_m)
        return np.isfinite(t_err)

    def select(self, model: Any, settings: SelectionSettings) -> Selection:
        """The adaptive schedule of ``model``'s selector with ``settings`` over the world's
        scans (a selection every period from the newest scan, as the ``adaptive`` stage)."""
        from pipeline.runtime import Selector

        selector = Selector(model, settings)
        names = model.names
        values = np.empty((len(self), len(names)))
        kept: list[str] = []
        for i, scan in enumerate(self.scans):
            stamp = int(self.stamps_ns[i])
            due = selector.due(stamp)
            params = selector.update(scan.points_lidar, stamp)
            if due:
                kept.append(str(selector.last.get("kept", "")))
            values[i] = [params[n] for n in names]
        schedule = Schedule(np.arange(len(self), dtype=np.int32),
                            {n: values[:, j].copy() for j, n in enumerate(names)}, self.stamps_ns)
        return Selection(schedule, schedule.n_changes,
                         kept.count("novel") / max(1, len(kept)), edge_share(values, model.space))

    def run(self, params_or_schedule: Mapping[str, float] | Schedule, replica: int,
            replica_scale: float) -> tuple[F64, bool]:
        """(per-start-frame RTE (N,) [%], failed) of one run on replica ``replica``."""
        t_err, failed, _ = self.run_trajectory(params_or_schedule, replica, replica_scale)
        return t_err, failed

    def run_trajectory(self, params_or_schedule: Mapping[str, float] | Schedule, replica: int,
                       replica_scale: float) -> tuple[F64, bool, Any]:
        """``run`` and the run's Trajectory (None when it failed: an error, or a step above
        the jump limit where the world has one)."""
        from pipeline.evaluate.replicas import factors, perturbed, sequence_seed
        from pipeline.metrics.rte import per_frame_rte
        from pipeline.odometry import run_scans
        from pipeline.tuning.job import check_jump

        setting = params_or_schedule
        if replica > 0:
            f = factors(sequence_seed(self.name), replica, len(self.adapter.space.names),
                        replica_scale)
            setting = perturbed(params_or_schedule, self.adapter.space, f)
        try:
            traj = run_scans(self.adapter, self.scans, self.stamps_ns, setting, self.name)
            if self.jump_limit_m is not None:
                check_jump(traj, self.jump_limit_m)
        except OdometryError as exc:
            log.info("%s replica %d: %s", self.name, replica, exc)
            penalty = np.nan if self.penalty_pct is None else self.penalty_pct
            return np.where(self.scored, penalty, np.nan), True, None
        t_err, _ = per_frame_rte(self.gt, traj.T_world_lidar, self.length_m)
        return t_err, False, traj


def edge_share(values: F64, space: list[dict[str, Any]]) -> float:
    """The share of frames (rows of ``values`` (N, P)) with any parameter within 1 % of its
    range's width from a bound."""
    if not len(values):
        return math.nan
    low = np.array([float(s["low"]) for s in space])
    high = np.array([float(s["high"]) for s in space])
    margin = 0.01 * (high - low)
    near = (values <= low + margin) | (values >= high - margin)
    return float(near.any(axis=1).mean())
