"""The real-data study's outputs (``run_report``): the metrics JSON of every algorithm, fold and
test run (``studies.real.summary``), the plot data (a row per algorithm, fold and run) and the
top view of the fold the docs draw (the reference against baseline, fixed and adaptive).

Beside the ratios: the reference's floor (the SLAM system's own odometry, ``RealRun.odometry``,
scored against the reference on the same sub-trajectories), where the selector fell back (the
share of a run's scans it judged unfamiliar), how close a run's two halves come (the
in-distribution folds test on ground next to what they trained on) and the cost of every step
(trials run, by status, and the suite's odometry runs: counts, the same on every machine).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from studies.real.section import RealSection
from studies.real.summary import HeldOutRun, family_metrics, run_metrics, targets

if TYPE_CHECKING:
    from studies.real.settings import StudySettings

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ReportPaths:
    """Inputs and outputs of the report stage."""

    units: Path  # data/units (units.json, the unit MCAPs)
    results: Path  # results: <algorithm>/{units,folds/<fold>/{fixed,in_sample,suite}}
    metrics: Path  # metrics/real.json
    plot_data: Path  # plots/real.csv
    figure: Path  # report/real_topview.png


def run_report(paths: ReportPaths, settings: StudySettings) -> dict[str, Any]:
    """Every algorithm's figures (module docstring); writes the outputs, returns the metrics."""
    from pipeline.io_utils import atomic_write_text
    from pipeline.outputs import csv_text, write_json
    from studies.real.units import read_unit_records

    real = settings.real
    records = read_unit_records(paths.units)
    floors = {u.name: unit_floor(paths.units / f"{u.name}.mcap", *settings.floors[u.run])
              for u in records}
    by_algorithm = {a: algorithm_metrics(paths, a, real, floors, settings.trials.penalty_pct)
                    for a in real.algorithms}
    metrics = {"algorithms": list(real.algorithms), "replicas": real.replicas,
               "penalty_pct": settings.trials.penalty_pct,
               "failure_pct": {f"{k:g}": v for k, v in real.failure_pct.items()},
               "units": [u.to_json() for u in records], "halves": halves_apart(paths.units,
                                                                             records),
               "plot_fold": real.plot_fold, "by_algorithm": by_algorithm,
               "targets": targets(by_algorithm, real.targets)}
    write_json(paths.metrics, metrics)
    atomic_write_text(paths.plot_data, csv_text(run_rows(by_algorithm)))
    topview_figure(paths, real)
    return metrics


def algorithm_metrics(paths: ReportPaths, algorithm: str, real: RealSection,
                      floors: Mapping[str, F64], penalty_pct: float) -> dict[str, Any]:
    """One algorithm's test runs over every fold, its families' figures and its cost."""
    from studies.real.folds import folds
    from studies.real.units import read_units

    units = read_units(paths.units)
    runs, cost = [], {"unit_studies": trial_counts(paths.results / algorithm / "units")}
    for fold in folds(units, real):
        folder = paths.results / algorithm / "folds" / fold.name
        results = {r.name: r for r in read_suite(folder / "suite")}
        choice = json.loads((folder / "choice.json").read_text())
        for run, names in fold.test.items():
            test = test_run(run, fold.name, fold.family, [results[u] for u in names],
                            [paths.units / f"{u}.mcap" for u in names],
                            [floors[u] for u in names], real, penalty_pct)
            runs.append({**run_metrics(test, real.resamples, real.confidence, 0),
                         "selector": selector_use([results[u] for u in names]),
                         "k": choice["k"], "k_chosen_by": choice["chosen_by"]})
        cost[fold.name] = fold_cost(folder, results.values())
    families = {fam: family_metrics([r for r in runs if r["family"] == fam], real.confidence,
                                    real.resamples, 0)
                for fam in sorted({r["family"] for r in runs})}
    return {"runs": runs, "families": families, "cost": cost}


def trial_counts(folder: Path) -> dict[str, int]:
    """Trials run under a studies folder, by status (and ``all``)."""
    from pipeline.tuning.layout import read_trials_tables

    if not folder.is_dir():
        return {"all": 0}
    status = read_trials_tables(folder).column("status").to_pylist()
    return {"all": len(status), **{s: status.count(s) for s in sorted(set(status))}}


def fold_cost(folder: Path, results: Any) -> dict[str, Any]:
    """A fold's cost: trials of its joint study and its in-sample studies (one a test run of
    several units: ``in_sample/<run>/``), the suite's runs (settings x replicas + 1, per test
    unit) and the frames those ran."""
    runs = frames = 0
    for r in results:
        for t in r.t_err_pct.values():
            runs += len(t)
            frames += len(t) * r.frames
    in_sample = [trial_counts(d) for d in sorted((folder / "in_sample").glob("*/"))]
    return {"joint_trials": trial_counts(folder / "fixed"),
            "in_sample_trials": {k: sum(c.get(k, 0) for c in in_sample)
                                 for k in dict.fromkeys(["all", *(k for c in in_sample
                                                                  for k in c)])},
            "suite_runs": runs, "suite_frames": frames}


def selector_use(results: Sequence[Any]) -> dict[str, Any]:
    """Where the adaptive setting's selector fell back on a test run: the share of its scans
    judged unfamiliar (frame-weighted over the run's units) and its parameter changes."""
    picks = [(r.frames, r.selection.get("adaptive", {})) for r in results]
    frames = sum(n for n, _ in picks)
    novel = sum(n * float(s.get("novel_share", 0.0)) for n, s in picks)
    return {"novel_share": novel / frames if frames else None,
            "changes": int(sum(s.get("changes", 0) for _, s in picks))}


def halves_apart(units_dir: Path, records: Sequence[Any]) -> dict[str, Any]:
    """Per run, how close its second half's reference comes to its first half's, away from
    where they meet (positions more than the run's L apart along the path): the least
    distance [m] (None: no such pair) and the share of second-half frames within 10 m of the
    first half. Every pair is measured (a run has a few hundred keyframes)."""
    from pipeline.geometry import path_distances
    from pipeline.sequence import SequenceReader

    out: dict[str, Any] = {}
    for run in dict.fromkeys(u.run for u in records):
        xyz, dist, half, length_m = [], [], [], 0.0
        for u in (u for u in records if u.run == run):
            with SequenceReader(units_dir / f"{u.name}.mcap") as reader:
                gt = reader.require_ground_truth("to measure how close its halves come")
                length_m = reader.info.length_m or 0.0
            xyz.append(gt[:, :3, 3])
            dist.append(u.start_m + path_distances(gt))
            half += [u.half] * len(gt)
        p, d, h = np.concatenate(xyz), np.concatenate(dist), np.array(half)
        first, second = h == "h1", h == "h2"
        if not first.any() or not second.any():
            continue
        apart_m = np.linalg.norm(p[second][:, None] - p[first][None], axis=2)  # (S, F)
        apart_m[np.abs(d[second][:, None] - d[first][None]) <= length_m] = np.inf
        gaps = apart_m.min(axis=1)
        out[run] = {"closest_m": float(gaps.min()) if np.isfinite(gaps).any() else None,
                    "second_within_10m": float(np.mean(gaps <= 10.0)), "length_m": length_m}
    return out


def test_run(run: str, fold: str, family: str, results: Sequence[Any],
             unit_paths: Sequence[Path], floors: Sequence[F64], real: RealSection,
             penalty_pct: float) -> HeldOutRun:
    """A test run of a fold: its units' runs and floors pooled along the start frames; the
    bootstrap's block is the median number of frames a sub-trajectory of the run's L spans."""
    settings = list(results[0].t_err_pct)
    t_err = {s: np.concatenate([r.t_err_pct[s] for r in results], axis=1) for s in settings}
    length_m, spans = 0.0, []
    for path in unit_paths:
        length_m, unit_spans = sub_trajectory_spans(path)
        spans.append(unit_spans)
    block = int(np.median(np.concatenate(spans))) if sum(map(len, spans)) else 1
    return HeldOutRun(run, fold, family, t_err, np.concatenate(floors), max(1, block),
                   real.failure_threshold(length_m), penalty_pct)


def sub_trajectory_spans(path: Path) -> tuple[float, NDArray[np.int64]]:
    """(the unit's L [m], the frames every sub-trajectory of it spans (one per start frame
    that has one))."""
    from pipeline.geometry import path_distances
    from pipeline.metrics.rte import segment_ends
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        gt = reader.require_ground_truth("to measure its sub-trajectories")
        length_m = reader.info.length_m
    if length_m is None:
        from pipeline.errors import InputError

        raise InputError(f"{path}: no RTE length of its own (the real runs' sources set one)")
    ends = segment_ends(path_distances(gt), length_m)
    starts = np.flatnonzero(ends >= 0)
    return length_m, ends[starts] - starts


def unit_floor(path: Path, odometry: Path, times: Path) -> F64:
    """(N,) per-start-frame RTE [%] of the SLAM system's own odometry over the unit's frames
    against the reference, at the unit's L: ``odometry`` (KITTI format) has a pose per line
    of the run's ``times`` file; the unit's frames are found by their stamps."""
    from pipeline.errors import InputError
    from pipeline.metrics.rte import per_frame_rte
    from pipeline.posefile import read_pose_file
    from pipeline.sequence import SequenceReader
    from pipeline.stamps import read_times

    with SequenceReader(path) as reader:
        gt = reader.require_ground_truth("to score the reference's floor against")
        stamps_ns = np.asarray(reader.stamps_ns, np.int64)
        length_m = reader.info.length_m
    every_ns = read_times(times, None)
    rows = np.searchsorted(every_ns, stamps_ns)
    if rows.max() >= len(every_ns) or not np.array_equal(every_ns[rows], stamps_ns):
        raise InputError(f"{path}: its stamps are not all lines of {times}")
    odom = read_pose_file(odometry, "kitti").T_world_x
    if len(odom) != len(every_ns):
        raise InputError(f"{odometry}: {len(odom)} poses for the {len(every_ns)} lines of "
                         f"{times}")
    t_err, _ = per_frame_rte(gt, odom[rows], float(length_m or 0.0))
    return t_err


def read_suite(folder: Path) -> list[Any]:
    """A fold's suite results (``studies.suites.runner.read_results``)."""
    from studies.suites.runner import read_results

    return read_results(folder)


def run_rows(by_algorithm: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """A row per algorithm, fold and test run: every ratio over the finished sub-trajectories
    and the pooled RTE of every setting."""
    def num(v: float | None) -> float | str:
        return "" if v is None else round(float(v), 6)

    rows = []
    for algorithm, m in by_algorithm.items():
        for r in m["runs"]:
            rows.append({"algorithm": algorithm, "fold": r["fold"], "family": r["family"],
                         "run": r["run"],
                         **{name: num(v["finished"]["value"]) for name, v in r["ratios"].items()},
                         **{f"{s}_pct": num(p["rte_pct"]) for s, p in r["pooled"].items()},
                         "floor_pct": num(r["floor"]["rte_pct"])})
    return rows


def topview_figure(paths: ReportPaths, real: RealSection) -> Path:
    """The plotted fold's test units from above: the reference against baseline, fixed and
    adaptive's nominal runs (each started at the reference's first pose), a panel per
    algorithm and test run."""
    from pipeline.outputs import SETTING_COLOURS, figure
    from pipeline.report.figures import aligned_positions
    from pipeline.sequence import read_ground_truth
    from pipeline.trajectory import read_trajectory
    from studies.real.folds import fold_named
    from studies.real.units import read_units

    fold = fold_named(read_units(paths.units), real, real.plot_fold)
    runs = list(fold.test)
    algorithms = list(real.algorithms)
    with figure(paths.figure, len(algorithms), len(runs),
                (4.0 * len(runs), 3.6 * len(algorithms))) as (fig, ax):
        for i, algorithm in enumerate(algorithms):
            suite = paths.results / algorithm / "folds" / fold.name / "suite"
            for j, run in enumerate(runs):
                a = ax[i, j]
                for k, unit in enumerate(fold.test[run]):
                    gt = read_ground_truth(paths.units / f"{unit}.mcap", "to draw")
                    a.plot(gt[:, 0, 3], gt[:, 1, 3], color=SETTING_COLOURS["ground truth"],
                           lw=1.2, label="reference" if k == 0 else None)
                    for setting in ("baseline", "fixed", "adaptive"):
                        f = suite / unit / f"{setting}.trajectory.parquet"
                        if f.is_file():
                            xyz = aligned_positions(gt, read_trajectory(f).T_world_lidar)
                            a.plot(xyz[:, 0], xyz[:, 1], color=SETTING_COLOURS[setting],
                                   lw=0.8, label=setting if k == 0 else None)
                a.set_aspect("equal", adjustable="datalim")
                a.set_title(f"{algorithm}: {run}", fontsize=9)
                if i == 0 and j == 0:
                    a.legend(fontsize=7)
        fig.suptitle(f"fold {fold.name}: the test units from above [m]")
    return paths.figure
