"""Whole trials against successive halving on a reduced run (docs/kitti.md).

Reads one or more finished runs of the pipeline (folders holding results/trials, results/fixed,
data/kitti_sim or another sequence folder with its index.json, and optionally
results/adaptune.duckdb with metrics/surrogate.json, and timing.log: ``TIME <stage> wall W user U
sys S`` lines) and prints, per run:

- frames: the fraction of the frames of every study its trials ran (a stopped trial: its
  trajectories, none for a sequence it did not start; a failed one: none written, counted
  whole);
- the best RTE found per training sequence (the best ok trial's objective) and its median;
- the surrogate's leave-one-sequence-out MAE and regret (metrics/surrogate.json);
- coverage of the parameter space per frame: the distinct trials with a row at each frame
  (``surrogate_rows``), over the first and the last third of every sequence's frames, and the
  share of those rows whose target is above the sequence's median trial RTE (bad parameter
  sets: what a late frame loses when only promoted trials reach it);
- the CPU by stage of timing.log.

``python experiments/fidelity.py RUN [RUN ...]``
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

from pipeline.sequence import SequenceReader
from pipeline.tuning.layout import JOINT_SEQUENCE, trajectory_path, trials_files


def frames_run(out: Path, sequences: dict[str, Path]) -> dict[str, dict[str, float]]:
    """Per study of the trials folder ``out`` (``<algorithm> <study>``): its trials, stopped
    (pruned) and failed ones, the fraction of its sequences' frames they ran and the best ok
    trial's objective (RTE [%])."""
    import pyarrow.parquet as pq

    from pipeline.trajectory import read_trajectory

    frames = {name: _frames(path) for name, path in sequences.items()}
    studies: dict[str, dict[str, float]] = {}
    for algorithm, study, table in trials_files(out):
        t = pq.read_table(table).to_pydict()
        names = list(sequences) if study == JOINT_SEQUENCE else [study]
        ran = 0
        for trial, status in zip(t["trial"], t["status"], strict=True):
            for name in names:
                path = trajectory_path(out, algorithm, name, trial)
                unrun = 0 if status == "pruned" else frames[name]  # a rung of whole sequences
                ran += len(read_trajectory(path)) if path.is_file() else unrun
        ok = [o for o, s in zip(t["objective"], t["status"], strict=True) if s == "ok"]
        studies[f"{algorithm} {study}"] = {
            "trials": len(t["trial"]), "pruned": t["status"].count("pruned"),
            "failed": t["status"].count("failed"),
            "fraction": ran / (len(t["trial"]) * sum(frames[n] for n in names)),
            "best": min(ok, default=float("nan"))}
    return studies


def _frames(path: Path) -> int:
    """The frames of the sequence MCAP ``path``."""
    with SequenceReader(path) as reader:
        return len(reader)


def coverage(db: Path) -> dict[str, dict[str, float]]:
    """Per training sequence: distinct trials with a row per frame (mean over the first and
    the last third of its frames with rows) and the share of bad rows (target above the
    sequence's median trial RTE) there."""
    import duckdb

    con = duckdb.connect(str(db), read_only=True)
    try:
        rows = con.execute("""
            SELECT sequence, frame, count(DISTINCT (algorithm, trial)), list(y)
            FROM surrogate_rows GROUP BY sequence, frame ORDER BY sequence, frame""").fetchall()
        medians = dict(con.execute("""
            SELECT sequence, median(objective) FROM trials
            WHERE study = 'trials' AND status = 'ok' GROUP BY sequence""").fetchall())
    finally:
        con.close()
    out: dict[str, dict[str, float]] = {}
    for seq in sorted({r[0] for r in rows}):
        mine = [r for r in rows if r[0] == seq]
        third = max(1, len(mine) // 3)
        early, late = mine[:third], mine[-third:]
        med = medians.get(seq, float("nan"))

        def bad(part: list[tuple[object, ...]], med: float = med) -> float:
            ys = np.concatenate([np.asarray(r[3], float) for r in part])
            return float(np.mean(ys > med))

        out[seq] = {"frames": len(mine), "early_trials": float(np.mean([r[2] for r in early])),
                    "late_trials": float(np.mean([r[2] for r in late])),
                    "early_bad": bad(early), "late_bad": bad(late),
                    "groups": len({r[2] for r in mine})}
    return out


def stage_cpu(run: Path) -> dict[str, float]:
    """CPU seconds (user + sys, children included) of every stage in ``run``/timing.log."""
    log = run / "timing.log"
    if not log.is_file():
        return {}
    out = {}
    for m in re.finditer(r"TIME (\S+) wall (\S+) user (\S+) sys (\S+)", log.read_text()):
        out[m.group(1)] = float(m.group(3)) + float(m.group(4))
    return out


def report(run: Path) -> list[str]:
    """The lines of one run (module docstring)."""
    from pipeline.sequence_index import read_index

    folders = (run / "data/kitti_sim", run / "data/kitti", run / "data/sequences")
    indexes = (read_index(p) for p in folders if (p / "index.json").is_file())
    index = next((i for i in indexes if i.splits.get("train")), None)  # each index read once
    if index is None:
        raise SystemExit(f"{run}: no sequence folder with a training split (data/kitti_sim, "
                         "data/kitti or data/sequences, with its index.json)")
    train = {Path(p).stem: Path(p) for p in index.paths("train")}
    trials = frames_run(run / "results/trials", train)
    joint = frames_run(run / "results/fixed", train)
    lines = [f"== {run}"]
    for name, s in {**trials, **joint}.items():
        lines.append(f"  {name:16s} trials {s['trials']:4.0f} pruned {s['pruned']:4.0f} "
                     f"failed {s['failed']:3.0f} frames run {100 * s['fraction']:5.1f} %  best "
                     f"{s['best']:.4g} %")
    lines.append("  median best RTE over training sequences: "
                 f"{np.median([s['best'] for s in trials.values()]):.4g} %")
    lines.append(f"  per-sequence studies: frames run "
                 f"{100 * np.mean([s['fraction'] for s in trials.values()]):.1f} % (mean)"
                 + "".join(f", joint {100 * s['fraction']:.1f} %" for s in joint.values()))
    if not (run / "metrics/surrogate.json").is_file():  # the verdict's: per sensor
        lines.append("  (no metrics/surrogate.json, results/adaptune.duckdb: studies only)")
    else:
        cv = json.loads((run / "metrics/surrogate.json").read_text())
        lines.append(f"  surrogate LOSO: MAE {cv['mae']:.4g}, RMSE {cv['rmse']:.4g}, regret "
                     f"{cv['regret_mean']:.4g}")
        for seq, c in coverage(run / "results/adaptune.duckdb").items():
            lines.append(
                f"  coverage {seq}: {c['frames']:.0f} frames, {c['groups']:.0f} trial sets; "
                f"distinct trials a frame, first third {c['early_trials']:.1f}, last third "
                f"{c['late_trials']:.1f}; rows above the median trial, first third "
                f"{100 * c['early_bad']:.0f} %, last third {100 * c['late_bad']:.0f} %")
    cpu = stage_cpu(run)
    if cpu:
        lines.append("  CPU by stage [s]: " + ", ".join(f"{k} {v:.0f}" for k, v in cpu.items()))
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args(argv)
    for run in args.runs:
        for line in report(run):
            print(line)


if __name__ == "__main__":
    main()
