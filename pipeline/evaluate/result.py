"""The evaluation's result model: every setting's per-start-frame RTE on every sequence, its
replicas and devkit segments, pooled per split (``Evaluation``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.metrics.kitti import LENGTHS_M, STEP_FRAMES, KittiSegments
from pipeline.odometry.base import Schedule
from pipeline.sequence import SequenceInfo
from pipeline.trajectory import Trajectory

SETTINGS = ("baseline", "fixed", "adaptive")


@dataclass
class Replica:
    """One replica run of a setting (``pipeline.evaluate.replicas``): per-start-frame RTE (N,)
    [%] and devkit segments, both None when the odometry failed."""

    t_err_pct: NDArray[np.float64] | None
    kitti: KittiSegments | None


@dataclass
class SettingScore:
    """One setting on one sequence: per-start-frame RTE (N,) [%] (NaN without a segment)."""

    setting: str
    sequence: str
    t_err_pct: NDArray[np.float64]
    labels: list[str | None]
    wall_time_s: float
    trajectory: Trajectory
    replicas: list[Replica] = field(default_factory=list)

    @property
    def rte_pct(self) -> float:
        """Mean RTE [%] over the start frames that have a segment."""
        return finite_mean(self.t_err_pct)

    @property
    def replica_rte_pct(self) -> list[float]:
        """Mean RTE [%] of every replica run (NaN where the odometry failed)."""
        return [math.nan if r.t_err_pct is None else finite_mean(r.t_err_pct)
                for r in self.replicas]

    def per_label(self) -> dict[str, float]:
        """Mean RTE [%] of the segments starting in each environment label."""
        labels = np.array([lab or "" for lab in self.labels])
        return {lab: finite_mean(self.t_err_pct[labels == lab])
                for lab in dict.fromkeys(labels.tolist()) if lab}


@dataclass
class Evaluation:
    """Scores of every setting on every evaluated sequence, plus what produced them.

    split_of: sequence name -> its split; kitti_segments: sequence -> setting -> its devkit
    segments (pooled per split by ``kitti_split``)."""

    algorithm: str
    length_m: float
    fixed_params: dict[str, float]
    baseline_params: dict[str, float]
    kitti_lengths_m: tuple[float, ...] = LENGTHS_M
    kitti_step_frames: int = STEP_FRAMES
    scores: list[SettingScore] = field(default_factory=list)
    schedules: dict[str, Schedule] = field(default_factory=dict)
    infos: dict[str, SequenceInfo] = field(default_factory=dict)
    ground_truth: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    kitti: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    split_of: dict[str, str] = field(default_factory=dict)
    kitti_segments: dict[str, dict[str, KittiSegments]] = field(default_factory=dict)

    @property
    def sequences(self) -> list[str]:
        return list(self.infos)

    @property
    def splits(self) -> list[str]:
        """The evaluated splits, in the order given (the headline one first)."""
        return list(dict.fromkeys(self.split_of[n] for n in self.sequences))

    def in_split(self, split: str | None) -> list[str]:
        """The sequences of ``split`` (None: all)."""
        return [n for n in self.sequences if split is None or self.split_of[n] == split]

    def score(self, setting: str, sequence: str) -> SettingScore:
        return next(s for s in self.scores if s.setting == setting and s.sequence == sequence)

    def _of(self, setting: str, split: str | None) -> list[SettingScore]:
        names = set(self.in_split(split))
        return [s for s in self.scores if s.setting == setting and s.sequence in names]

    def pooled(self, setting: str, split: str | None = None) -> NDArray[np.float64]:
        """Per-start-frame RTE [%] of ``setting`` over the sequences of ``split`` (None: all),
        concatenated."""
        return np.concatenate([s.t_err_pct for s in self._of(setting, split)])

    def overall(self, setting: str, split: str | None = None) -> float:
        """Mean RTE [%] of ``setting`` over the segments of ``split`` (None: all) pooled."""
        return finite_mean(self.pooled(setting, split))

    def overall_per_label(self, setting: str, split: str | None = None) -> dict[str, float]:
        """Mean RTE [%] of ``setting`` per environment label, ``split`` (None: all) pooled."""
        labels = np.concatenate([[lab or "" for lab in s.labels]
                                 for s in self._of(setting, split)])
        errs = self.pooled(setting, split)
        return {lab: finite_mean(errs[labels == lab])
                for lab in dict.fromkeys(labels.tolist()) if lab}

    def kitti_split(self, setting: str, split: str) -> dict[str, float]:
        """The devkit metric of ``setting`` over every segment of the ``split`` sequences pooled
        (as the devkit pools a benchmark): t_err [%], r_err [deg/100 m], segment count."""
        seg = KittiSegments.concat([self.kitti_segments[n][setting]
                                    for n in self.in_split(split)])
        return kitti_summary(seg)

    @property
    def replicas(self) -> int:
        """Replica runs per setting and sequence (0: none)."""
        return max((len(s.replicas) for s in self.scores), default=0)

    def replica_runs(self, setting: str, split: str) -> dict[str, list[float]]:
        """The ``split``'s pooled figures of ``setting`` for the nominal run and each replica
        r (the r-th replica of every sequence pooled; NaN when one of them failed): mean
        per-start-frame RTE [%] (``rte_pct``) and devkit t_err [%] (``kitti_t_err_pct``)."""
        scores = self._of(setting, split)
        rte, kitti = [self.overall(setting, split)], [self.kitti_split(setting, split)["t_err_pct"]]
        for r in range(self.replicas):
            ok = [(run.t_err_pct, run.kitti) for run in (s.replicas[r] for s in scores)
                  if run.t_err_pct is not None and run.kitti is not None]
            failed = len(ok) < len(scores)
            rte.append(math.nan if failed else finite_mean(np.concatenate([e for e, _ in ok])))
            kitti.append(math.nan if failed else KittiSegments.concat([k for _, k in ok]).t_err_pct)
        return {"rte_pct": rte, "kitti_t_err_pct": kitti}


def finite_mean(values: NDArray[np.float64]) -> float:
    """Mean of the finite values (NaN without one): an RTE [%] over start frames."""
    v = values[np.isfinite(values)]
    return float(v.mean()) if len(v) else math.nan


def kitti_summary(seg: KittiSegments) -> dict[str, float]:
    """Devkit t_err [%], r_err [deg/100 m] and segment count of pooled segments."""
    return {"t_err_pct": seg.t_err_pct, "r_err_deg_per_100m": 100.0 * seg.r_err_deg_per_m,
            "segments": len(seg)}
