"""Running baseline and fixed, reading adaptive, scoring all three on the evaluated splits (the
paper's Tables I and II).

``evaluate`` runs the baseline (the adapter's defaults) and the fixed parameters (the best trial
of the joint SMBO), reads the adaptive trajectory and schedule written by the ``adaptive``
stage, and scores all three with the same per-start-frame RTE (``length_m``; a sequence with
an RTE length of its own, ``SequenceInfo.length_m``, at that one), overall and per
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
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError, OdometryError
from pipeline.evaluate.result import (
    Evaluation,
    Replica,
    SettingScore,
    kitti_summary,
)
from pipeline.evaluate.section import EvaluateSection
from pipeline.metrics.kitti import KittiSegments
from pipeline.metrics.rte import check_scorable, per_frame_rte
from pipeline.metrics.section import DevkitSection
from pipeline.odometry.base import Schedule
from pipeline.sequence import SequenceInfo, SequenceReader
from pipeline.trajectory import Trajectory, read_trajectory, write_trajectory

log = logging.getLogger(__name__)


def best_fixed_params(trials_dir: Path, algorithm: str | None = None,
                      study: str | None = None) -> tuple[str, dict[str, float]]:
    """(algorithm, parameters) of the best 'ok' trial of the joint SMBO under ``trials_dir``
    (``study``: of that sequence's own study instead)."""
    from pipeline.tuning.layout import JOINT_SEQUENCE, best_trial, read_trials_tables

    table = read_trials_tables(trials_dir)
    sequence = JOINT_SEQUENCE if study is None else study
    rows = [r for r in table.to_pylist() if r["sequence"] == sequence
            and (algorithm is None or r["algorithm"] == algorithm)]
    if not rows:
        what = "joint trials table" if study is None else f"trials table of {study!r}"
        raise InputError(f"{trials_dir}: no {what}"
                         f"{f' for {algorithm}' if algorithm else ''} (run the `fixed` stage)")
    tid = best_trial((r["trial"], r["status"], r["objective"]) for r in rows)
    if tid is None:
        raise InputError(f"{trials_dir}: no successful joint trial to take fixed parameters from")
    best = next(r for r in rows if r["trial"] == tid)
    return best["algorithm"], {k: float(v) for k, v in json.loads(best["params_json"]).items()}


def evaluate(sequences: list[Path], algorithm: str, fixed_params: Mapping[str, float],
             adaptive_dir: Path, out_dir: Path, settings: EvaluateSection,
             fixed_dir: Path | None = None,
             split_of: Mapping[str, str] | None = None) -> Evaluation:
    """Run baseline and fixed, load adaptive, score all three on every sequence.

    ``fixed_dir``: the joint study's output, whose stored parameter space (its defaults: the
    baseline) and adapter options are used; None: the adapter's built-in space and options.
    split_of: sequence name -> split (default: every sequence in ``settings.splits[0]``).
    The baseline and fixed trajectories go to ``out_dir/<sequence>/<setting>.parquet``.
    ``settings.workers`` sequences are scored at a time (spawned processes; every figure is the
    same for any number).
    """
    from pipeline.executor import map_in_processes

    for path in sequences:  # one too short would drop out of its split's figures unseen
        gt, info = _ground_truth(path)
        check_scorable(gt, info.scored_length_m(settings.length_m), str(path))
    adapter = evaluated_adapter(algorithm, fixed_dir)
    result = Evaluation(algorithm, settings.length_m, adapter.space.validate(fixed_params),
                        adapter.space.defaults(), settings.devkit.lengths_m,
                        settings.devkit.step_frames)
    jobs = [(path, algorithm, fixed_dir, result.baseline_params,
             result.fixed_params, adaptive_dir, out_dir, settings) for path in sequences]
    scored = map_in_processes(_score_sequence, jobs, settings.workers)
    for path, seq in zip(sequences, scored, strict=True):
        name = path.stem
        result.infos[name], result.ground_truth[name] = seq.info, seq.ground_truth
        result.split_of[name] = (split_of or {}).get(name, settings.splits[0])
        result.scores.extend(seq.scores)
        result.schedules[name] = seq.schedule
        result.kitti_segments[name] = seq.kitti_segments
        result.kitti[name] = {s: kitti_summary(seg) for s, seg in seq.kitti_segments.items()}
    return result


def evaluated_adapter(algorithm: str, fixed_dir: Path | None) -> Any:
    """The adapter as the studies ran it: the space they searched (its defaults are the
    baseline) and their adapter options, read from the joint study's output; the built-in
    space and options without one."""
    from pipeline.odometry.registry import build_adapter
    from pipeline.tuning.table import read_adapter_options, read_space

    if fixed_dir is None:
        return build_adapter(algorithm)
    return build_adapter(algorithm, read_adapter_options(fixed_dir, algorithm),
                         read_space(fixed_dir, algorithm))


@dataclass
class _SequenceResult:
    """What scoring one sequence gives ``evaluate``."""

    info: SequenceInfo
    ground_truth: NDArray[np.float64]
    scores: list[SettingScore]
    schedule: Schedule
    kitti_segments: dict[str, KittiSegments]


def _score_sequence(path: Path, algorithm: str,
                    fixed_dir: Path | None, baseline_params: dict[str, float],
                    fixed_params: dict[str, float], adaptive_dir: Path, out_dir: Path,
                    settings: EvaluateSection) -> _SequenceResult:
    """Baseline and fixed run on ``path``, the adaptive run read back, all three scored."""
    adapter = evaluated_adapter(algorithm, fixed_dir)
    name = path.stem
    gt, info = _ground_truth(path)
    length_m = info.scored_length_m(settings.length_m)
    labels = [info.label_of(i) for i in range(len(gt))]
    runs = {"baseline": _run_fixed(adapter, path, baseline_params, out_dir, "baseline"),
            "fixed": _run_fixed(adapter, path, fixed_params, out_dir, "fixed"),
            "adaptive": _read_adaptive(adaptive_dir / name, algorithm)}
    scores = []
    for setting, (traj, wall) in runs.items():
        t_err, _ = per_frame_rte(gt, traj.T_world_lidar, length_m)
        scores.append(SettingScore(setting, name, t_err, labels, wall, traj))
        log.info("%s %s: %.3f %% RTE (%.1f s)", name, setting, scores[-1].rte_pct, wall)
    schedule = Schedule.read(adaptive_dir / name / "schedule.parquet")
    nominal: dict[str, Mapping[str, float] | Schedule] = {
        "baseline": baseline_params, "fixed": fixed_params, "adaptive": schedule}
    for score in scores if settings.replicas else []:
        score.replicas = run_replicas(adapter, path, gt, nominal[score.setting], settings,
                                      length_m)
    return _SequenceResult(
        info, gt, scores, schedule,
        _kitti_segments(gt, {s: t for s, (t, _) in runs.items()}, settings.devkit))


def run_replicas(adapter: Any, path: Path, gt: NDArray[np.float64],
                 params_or_schedule: Mapping[str, float] | Schedule,
                 settings: EvaluateSection, length_m: float | None = None) -> list[Replica]:
    """``settings.replicas`` runs of one setting on ``path`` with its parameters moved by the
    replicas' factors (``pipeline.evaluate.replicas``), scored like the nominal run (at
    ``length_m``, the sequence's L; None: ``settings.length_m``)."""
    length_m = settings.length_m if length_m is None else length_m
    from pipeline.evaluate.replicas import factors, perturbed, sequence_seed
    from pipeline.metrics.kitti import kitti_errors
    from pipeline.odometry import run_sequence

    out = []
    for r in range(1, settings.replicas + 1):
        f = factors(sequence_seed(path.stem), r, len(adapter.space.names), settings.replica_scale)
        try:
            traj = run_sequence(adapter, path, perturbed(params_or_schedule, adapter.space, f))
        except OdometryError:
            out.append(Replica(None, None))
            continue
        t_err, _ = per_frame_rte(gt, traj.T_world_lidar, length_m)
        out.append(Replica(t_err, kitti_errors(gt, traj.T_world_lidar, settings.devkit.lengths_m,
                                               settings.devkit.step_frames)))
    return out


def _ground_truth(path: Path) -> tuple[NDArray[np.float64], SequenceInfo]:
    with SequenceReader(path) as reader:
        return reader.require_ground_truth("to evaluate against"), reader.info


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
    """The adaptive stage's trajectory and wall time (NaN: ``run.json`` keeps none, the adaptive
    stage's record does); InputError when it was another algorithm."""
    meta_path = folder / "run.json"
    if not meta_path.is_file():
        raise InputError(f"{meta_path}: no adaptive run (run the `adaptive` stage)")
    meta = json.loads(meta_path.read_text(encoding="utf-8"))
    if meta.get("algorithm") != algorithm:
        raise InputError(f"{meta_path}: adaptive run of {meta.get('algorithm')!r}, "
                         f"the fixed parameters are for {algorithm!r}")
    return read_trajectory(folder / "trajectory.parquet"), float(meta.get("wall_time_s", "nan"))


def _kitti_segments(gt: NDArray[np.float64], trajectories: Mapping[str, Trajectory],
                    devkit: DevkitSection) -> dict[str, KittiSegments]:
    """Devkit segments of every setting (the lengths that fit)."""
    from pipeline.metrics.kitti import kitti_errors

    return {setting: kitti_errors(gt, traj.T_world_lidar, devkit.lengths_m, devkit.step_frames)
            for setting, traj in trajectories.items()}




