"""Baseline vs fixed vs adaptive on the evaluated splits (the paper's Tables I and II).

``evaluate`` runs the baseline (the adapter's defaults) and the fixed parameters (the best trial
of the joint SMBO), reads the adaptive trajectory and schedule written by the ``adaptive``
stage, and scores all three with the same per-start-frame RTE (``length_m``), overall and per
environment label (a segment counts for the label of its start frame), plus the KITTI devkit
metric with the devkit lengths that fit into the sequence. Several splits can be evaluated
(``evaluate.splits``, e.g. the training and the test sequences of the KITTI protocol): every
figure is also given per split, the devkit one pooled over the split's segments as the devkit
pools a benchmark. The headline figures (``rte_pct``, ``ratio``) are those of the first split
listed, all its segments pooled.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator

from pipeline.config import Section
from pipeline.errors import InputError, OdometryError
from pipeline.evaluation.kitti import LENGTHS_M, KittiSegments
from pipeline.evaluation.rte import check_scorable, per_frame_rte
from pipeline.odometry.base import Schedule
from pipeline.sequence import SequenceInfo, SequenceReader
from pipeline.trajectory import Trajectory, read_trajectory, write_trajectory

log = logging.getLogger(__name__)

SETTINGS = ("baseline", "fixed", "adaptive")


class EvaluateSection(Section):
    """params.yaml ``evaluate`` (also read by the ``adaptive`` stage for its splits).

    splits: the splits of index.json to evaluate on, the headline one first (e.g.
    [validation, train] for the KITTI protocol's test and training sequences); length_m: RTE
    segment length [m] (the trials' L); kitti_lengths_m: devkit lengths to try (those longer
    than a sequence are left out, as the devkit does); workers: sequences run at a time by the
    ``adaptive`` and ``evaluate`` stages (processes; the same results for any number);
    replicas: extra runs of every setting with the parameters moved by at most
    ``replica_scale`` (relative; ``pipeline.report.replicas``; 0: none).
    """

    splits: list[str] = Field(default_factory=lambda: ["validation"], min_length=1)
    length_m: float = Field(25.0, gt=0)
    kitti_lengths_m: tuple[float, ...] = LENGTHS_M
    workers: int = Field(default=2, ge=1)
    replicas: int = Field(default=0, ge=0)
    replica_scale: float = Field(default=0.005, gt=0, le=0.1)

    @field_validator("splits")
    @classmethod
    def _distinct(cls, v: list[str]) -> list[str]:
        twice = sorted({s for s in v if v.count(s) > 1})
        if twice:
            raise ValueError(f"splits must be distinct, {twice[0]!r} is listed twice")
        return v


@dataclass
class Replica:
    """One replica run of a setting (``pipeline.report.replicas``): per-start-frame RTE (N,)
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
        return _mean(self.t_err_pct)

    @property
    def replica_rte_pct(self) -> list[float]:
        """Mean RTE [%] of every replica run (NaN where the odometry failed)."""
        return [math.nan if r.t_err_pct is None else _mean(r.t_err_pct) for r in self.replicas]

    def per_label(self) -> dict[str, float]:
        """Mean RTE [%] of the segments starting in each environment label."""
        labels = np.array([lab or "" for lab in self.labels])
        return {lab: _mean(self.t_err_pct[labels == lab])
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
        return _mean(self.pooled(setting, split))

    def overall_per_label(self, setting: str, split: str | None = None) -> dict[str, float]:
        """Mean RTE [%] of ``setting`` per environment label, ``split`` (None: all) pooled."""
        labels = np.concatenate([[lab or "" for lab in s.labels]
                                 for s in self._of(setting, split)])
        errs = self.pooled(setting, split)
        return {lab: _mean(errs[labels == lab]) for lab in dict.fromkeys(labels.tolist()) if lab}

    def kitti_split(self, setting: str, split: str) -> dict[str, float]:
        """The devkit metric of ``setting`` over every segment of the ``split`` sequences pooled
        (as the devkit pools a benchmark): t_err [%], r_err [deg/100 m], segment count."""
        seg = KittiSegments.concat([self.kitti_segments[n][setting]
                                    for n in self.in_split(split)])
        return _kitti_summary(seg)

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
            rte.append(math.nan if failed else _mean(np.concatenate([e for e, _ in ok])))
            kitti.append(math.nan if failed else KittiSegments.concat([k for _, k in ok]).t_err_pct)
        return {"rte_pct": rte, "kitti_t_err_pct": kitti}


def _mean(values: NDArray[np.float64]) -> float:
    v = values[np.isfinite(values)]
    return float(v.mean()) if len(v) else math.nan


def best_fixed_params(trials_dir: Path,
                      algorithm: str | None = None) -> tuple[str, dict[str, float]]:
    """(algorithm, parameters) of the best 'ok' trial of the joint SMBO under ``trials_dir``."""
    from pipeline.evaluation.trials import JOINT_SEQUENCE, best_trial, read_trials_tables

    table = read_trials_tables(trials_dir)
    rows = [r for r in table.to_pylist() if r["sequence"] == JOINT_SEQUENCE
            and (algorithm is None or r["algorithm"] == algorithm)]
    if not rows:
        raise InputError(f"{trials_dir}: no joint trials table"
                         f"{f' for {algorithm}' if algorithm else ''} (run the `fixed` stage)")
    tid = best_trial((r["trial"], r["status"], r["objective"]) for r in rows)
    if tid is None:
        raise InputError(f"{trials_dir}: no successful joint trial to take fixed parameters from")
    best = next(r for r in rows if r["trial"] == tid)
    return best["algorithm"], {k: float(v) for k, v in json.loads(best["params_json"]).items()}


def evaluate(sequences: list[Path], algorithm: str, fixed_params: Mapping[str, float],
             adaptive_dir: Path, out_dir: Path, settings: EvaluateSection,
             adapter_options: Mapping[str, object] | None = None,
             fixed_dir: Path | None = None,
             split_of: Mapping[str, str] | None = None) -> Evaluation:
    """Run baseline and fixed, load adaptive, score all three on every sequence.

    ``fixed_dir``: the joint study's output, whose stored parameter space (its defaults: the
    baseline) is used; None: the adapter's built-in space.
    split_of: sequence name -> split (default: every sequence in ``settings.splits[0]``).
    The baseline and fixed trajectories go to ``out_dir/<sequence>/<setting>.parquet``.
    ``settings.workers`` sequences are scored at a time (spawned processes; every figure is the
    same for any number).
    """
    from pipeline.executor import map_in_processes

    for path in sequences:  # one too short would drop out of its split's figures unseen
        check_scorable(_ground_truth(path)[0], settings.length_m, str(path))
    adapter = study_adapter(algorithm, adapter_options, fixed_dir)
    result = Evaluation(algorithm, settings.length_m, adapter.space.validate(fixed_params),
                        adapter.space.defaults(), settings.kitti_lengths_m)
    jobs = [(path, algorithm, adapter_options, fixed_dir, result.baseline_params,
             result.fixed_params, adaptive_dir, out_dir, settings) for path in sequences]
    scored = map_in_processes(_score_sequence, jobs, settings.workers)
    for path, seq in zip(sequences, scored, strict=True):
        name = path.stem
        result.infos[name], result.ground_truth[name] = seq.info, seq.ground_truth
        result.split_of[name] = (split_of or {}).get(name, settings.splits[0])
        result.scores.extend(seq.scores)
        result.schedules[name] = seq.schedule
        result.kitti_segments[name] = seq.kitti_segments
        result.kitti[name] = {s: _kitti_summary(seg) for s, seg in seq.kitti_segments.items()}
    return result


def study_adapter(algorithm: str, adapter_options: Mapping[str, object] | None,
                  fixed_dir: Path | None) -> Any:
    """The adapter with the space the studies searched (its defaults are the baseline), read
    from the joint study's output; the built-in space without one."""
    from pipeline.odometry import get_adapter
    from pipeline.odometry.base import with_space
    from pipeline.tuning.table import read_space

    adapter = get_adapter(algorithm, **dict(adapter_options or {}))
    return adapter if fixed_dir is None else with_space(adapter, read_space(fixed_dir, algorithm))


@dataclass
class _SequenceResult:
    """What scoring one sequence gives ``evaluate``."""

    info: SequenceInfo
    ground_truth: NDArray[np.float64]
    scores: list[SettingScore]
    schedule: Schedule
    kitti_segments: dict[str, KittiSegments]


def _score_sequence(path: Path, algorithm: str, adapter_options: Mapping[str, object] | None,
                    fixed_dir: Path | None, baseline_params: dict[str, float],
                    fixed_params: dict[str, float], adaptive_dir: Path, out_dir: Path,
                    settings: EvaluateSection) -> _SequenceResult:
    """Baseline and fixed run on ``path``, the adaptive run read back, all three scored."""
    adapter = study_adapter(algorithm, adapter_options, fixed_dir)
    name = path.stem
    gt, info = _ground_truth(path)
    labels = [info.label_of(i) for i in range(len(gt))]
    runs = {"baseline": _run_fixed(adapter, path, baseline_params, out_dir, "baseline"),
            "fixed": _run_fixed(adapter, path, fixed_params, out_dir, "fixed"),
            "adaptive": _read_adaptive(adaptive_dir / name, algorithm)}
    scores = []
    for setting, (traj, wall) in runs.items():
        t_err, _ = per_frame_rte(gt, traj.T_world_lidar, settings.length_m)
        scores.append(SettingScore(setting, name, t_err, labels, wall, traj))
        log.info("%s %s: %.3f %% RTE (%.1f s)", name, setting, scores[-1].rte_pct, wall)
    schedule = Schedule.read(adaptive_dir / name / "schedule.parquet")
    nominal: dict[str, Mapping[str, float] | Schedule] = {
        "baseline": baseline_params, "fixed": fixed_params, "adaptive": schedule}
    for score in scores if settings.replicas else []:
        score.replicas = run_replicas(adapter, path, gt, nominal[score.setting], settings)
    return _SequenceResult(
        info, gt, scores, schedule,
        _kitti_segments(gt, {s: t for s, (t, _) in runs.items()}, settings.kitti_lengths_m))


def run_replicas(adapter: Any, path: Path, gt: NDArray[np.float64],
                 params_or_schedule: Mapping[str, float] | Schedule,
                 settings: EvaluateSection) -> list[Replica]:
    """``settings.replicas`` runs of one setting on ``path`` with its parameters moved by the
    replicas' factors (``pipeline.report.replicas``), scored like the nominal run."""
    from pipeline.evaluation.kitti import kitti_errors
    from pipeline.odometry import run_sequence
    from pipeline.report.replicas import factors, perturbed, sequence_seed

    out = []
    for r in range(1, settings.replicas + 1):
        f = factors(sequence_seed(path.stem), r, len(adapter.space.names), settings.replica_scale)
        try:
            traj = run_sequence(adapter, path, perturbed(params_or_schedule, adapter.space, f))
        except OdometryError:
            out.append(Replica(None, None))
            continue
        t_err, _ = per_frame_rte(gt, traj.T_world_lidar, settings.length_m)
        out.append(Replica(t_err, kitti_errors(gt, traj.T_world_lidar, settings.kitti_lengths_m)))
    return out


def _ground_truth(path: Path) -> tuple[NDArray[np.float64], SequenceInfo]:
    with SequenceReader(path) as reader:
        gt, info = reader.ground_truth(), reader.info
    if gt is None:
        raise InputError(f"{path}: validation sequence has no ground truth")
    return gt, info


def _run_fixed(adapter: Any, path: Path, params: Mapping[str, float], out_dir: Path,
               setting: str) -> tuple[Trajectory, float]:
    """Run ``adapter`` with constant ``params``; write and return the trajectory, wall time."""
    from pipeline.odometry import run_sequence

    t0 = time.perf_counter()
    traj = run_sequence(adapter, path, params)
    wall = time.perf_counter() - t0
    write_trajectory(out_dir / path.stem / f"{setting}.parquet", traj,
                     {"setting": setting, "algorithm": adapter.name, "sequence": path.stem,
                      "params_json": json.dumps(dict(params), sort_keys=True)})
    return traj, wall


def _read_adaptive(folder: Path, algorithm: str) -> tuple[Trajectory, float]:
    """The adaptive stage's trajectory and wall time; InputError when it was another algorithm."""
    meta_path = folder / "run.json"
    if not meta_path.is_file():
        raise InputError(f"{meta_path}: no adaptive run (run the `adaptive` stage)")
    meta = json.loads(meta_path.read_text(encoding="utf-8"))
    if meta.get("algorithm") != algorithm:
        raise InputError(f"{meta_path}: adaptive run of {meta.get('algorithm')!r}, "
                         f"the fixed parameters are for {algorithm!r}")
    return read_trajectory(folder / "trajectory.parquet"), float(meta["wall_time_s"])


def _kitti_segments(gt: NDArray[np.float64], trajectories: Mapping[str, Trajectory],
                    lengths_m: tuple[float, ...]) -> dict[str, KittiSegments]:
    """Devkit segments of every setting (the lengths that fit)."""
    from pipeline.evaluation.kitti import kitti_errors

    return {setting: kitti_errors(gt, traj.T_world_lidar, lengths_m)
            for setting, traj in trajectories.items()}


def _kitti_summary(seg: KittiSegments) -> dict[str, float]:
    """Devkit t_err [%], r_err [deg/100 m] and segment count of pooled segments."""
    return {"t_err_pct": seg.t_err_pct, "r_err_deg_per_100m": 100.0 * seg.r_err_deg_per_m,
            "segments": len(seg)}


# ------------------------------------------------------------------------------- metrics


def trials_summary(studies: Mapping[str, Path]) -> dict[str, dict[str, float]]:
    """Trial counts by status (failed: the odometry failed; pruned: stopped early as hopeless;
    lost: to the machinery) and total wall time [s] of every SMBO output folder."""
    from pipeline.evaluation.trials import read_trials_tables

    out = {}
    for study, folder in studies.items():
        rows = read_trials_tables(folder).to_pylist()
        out[study] = {"studies": len({(r["algorithm"], r["sequence"]) for r in rows}),
                      "trials": len(rows),
                      **{status: sum(r["status"] == status for r in rows)
                         for status in ("failed", "pruned", "lost")},
                      "wall_time_s": float(sum(r["wall_time_s"] for r in rows))}
    return out


def _ratio(values: Mapping[str, float]) -> dict[str, float]:
    return {"adaptive_vs_baseline": values["adaptive"] / values["baseline"],
            "adaptive_vs_fixed": values["adaptive"] / values["fixed"]}


def split_metrics(ev: Evaluation, split: str) -> dict[str, Any]:
    """The figures of one split: its sequences, RTE [%] pooled (overall, per label), the
    ratios, and the devkit metric pooled over the split's segments with its ratios."""
    rte = {s: ev.overall(s, split) for s in SETTINGS}
    kitti = {s: ev.kitti_split(s, split) for s in SETTINGS}
    out = {"sequences": ev.in_split(split), "rte_pct": rte, "ratio": _ratio(rte),
           "rte_pct_per_label": {s: ev.overall_per_label(s, split) for s in SETTINGS},
           "kitti": kitti,
           "kitti_ratio": _ratio({s: k["t_err_pct"] for s, k in kitti.items()})}
    if ev.replicas:
        out["replicas"] = {s: ev.replica_runs(s, split) for s in SETTINGS}
    return out


def metrics(ev: Evaluation, trials: Mapping[str, Mapping[str, float]]) -> dict[str, Any]:
    """The JSON of ``dvc metrics show``: RTE per setting (headline split: overall, per label;
    per split; per sequence), ratios, KITTI metric, failed-trial counts and wall times."""
    splits = {split: split_metrics(ev, split) for split in ev.splits}
    head = splits[ev.splits[0]]
    return {
        "algorithm": ev.algorithm,
        "length_m": ev.length_m,
        "replicas": ev.replicas,
        "headline_split": ev.splits[0],
        "kitti_lengths_m": list(ev.kitti_lengths_m),
        "rte_pct": head["rte_pct"],
        "ratio": head["ratio"],
        "rte_pct_per_label": head["rte_pct_per_label"],
        "splits": splits,
        "sequences": {name: {
            "split": ev.split_of[name],
            "rte_pct": {s: ev.score(s, name).rte_pct for s in SETTINGS},
            "rte_pct_per_label": {s: ev.score(s, name).per_label() for s in SETTINGS},
            "kitti": ev.kitti[name],
            "wall_time_s": {s: ev.score(s, name).wall_time_s for s in SETTINGS},
            "parameter_changes": ev.schedules[name].n_changes,
            **({"replicas_rte_pct": {s: ev.score(s, name).replica_rte_pct for s in SETTINGS}}
               if ev.replicas else {}),
        } for name in ev.sequences},
        "params": {"baseline": ev.baseline_params, "fixed": ev.fixed_params},
        "trials": dict(trials),
    }
