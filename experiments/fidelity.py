"""Whole trials against successive halving on a reduced run (issue 33; docs/kitti.md).

Reads one or more finished runs of the pipeline (folders holding results/trials, results/fixed,
results/adaptune.duckdb, metrics/surrogate.json, data/kitti_sim or another sequence folder, and
optionally timing.log: ``TIME <stage> wall W user U sys S`` lines) and prints, per run:

- frames: the fraction of the frames of every study its trials ran (a stopped trial: its
  trajectories, none for a sequence it did not start; a failed one: none written, counted
  whole);
- the best RTE found per training sequence (the best ok trial's objective) and its median;
- the surrogate's leave-one-sequence-out MAE and regret (metrics/surrogate.json);
- coverage of the parameter space per frame: the distinct trials with a row at each frame
  (``surrogate_rows``), over the first and the last third of every sequence's frames, and the
  share of those rows whose target is above the sequence's median trial RTE (bad parameter
  sets: what a late frame loses when only promoted trials reach it);
- the cost check: CPU seconds the model predicts for the trials and the joint study (frames
  run x the per-frame CPU cost of the frame's environment, ``--costs`` JSON: {env:
  {"sampled": ms, "default": ms}} from ``python bench/run.py kitti``) beside the CPU the
  stages took (timing.log).

``python experiments/fidelity.py RUN [RUN ...] [--costs costs.json]``
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.sequence import SequenceReader
from pipeline.tuning.layout import JOINT_SEQUENCE, trajectory_path, trials_files


def frames_run(out: Path, sequences: dict[str, Path]) -> dict[str, dict[str, object]]:
    """Per study of the trials folder ``out``: its trials, the frames they ran per sequence
    and environment, and the fraction of frames run."""
    import pyarrow.parquet as pq

    from pipeline.trajectory import read_trajectory

    info = {name: _labels(path) for name, path in sequences.items()}
    studies: dict[str, dict[str, object]] = {}
    for algorithm, study, table in trials_files(out):
        t = pq.read_table(table).to_pydict()
        names = list(sequences) if study == JOINT_SEQUENCE else [study]
        ran_env: dict[str, int] = {}
        ran = total = 0
        for trial, status in zip(t["trial"], t["status"], strict=True):
            for name in names:
                labels = info[name]
                path = trajectory_path(out, algorithm, name, trial)
                unrun = 0 if status == "pruned" else len(labels)  # a rung of whole sequences
                n = len(read_trajectory(path)) if path.is_file() else unrun
                for env in labels[:n]:
                    ran_env[env] = ran_env.get(env, 0) + 1
                ran += n
                total += len(labels)
        studies[study] = {"trials": len(t["trial"]), "pruned": t["status"].count("pruned"),
                          "failed": t["status"].count("failed"), "fraction": ran / total,
                          "frames_by_env": ran_env,
                          "best": min((o for o, s in zip(t["objective"], t["status"],
                                                         strict=True) if s == "ok"),
                                      default=float("nan"))}
    return studies


def _labels(path: Path) -> list[str]:
    """The environment label of every frame of the sequence MCAP ``path``."""
    with SequenceReader(path) as reader:
        info = reader.info
        n = len(reader)
    return [info.label_of(f) or "unknown" for f in range(n)]


def coverage(db: Path) -> dict[str, dict[str, float]]:
    """Per training sequence: distinct trials with a row per frame (mean over the first and
    the last third of its frames with rows) and the share of bad rows (target above the
    sequence's median trial RTE) there."""
    import duckdb

    con = duckdb.connect(str(db), read_only=True)
    try:
        rows = con.execute("""
            SELECT sequence, frame, count(DISTINCT trial), list(y)
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


def predicted_cpu(study: dict[str, object], costs: dict[str, dict[str, float]]) -> float:
    """CPU seconds of a study's trials by the model: frames run x the sampled per-frame cost."""
    frames = study["frames_by_env"]
    assert isinstance(frames, dict)
    return sum(n * costs[env]["sampled"] / 1000 for env, n in frames.items())


def report(run: Path, costs: dict[str, dict[str, float]] | None) -> None:
    from pipeline.sequence_index import read_index

    folders = (run / "data/kitti_sim", run / "data/kitti", run / "data/sequences")
    indexes = (read_index(p) for p in folders if (p / "index.json").is_file())
    index = next(i for i in indexes if i.splits.get("train"))  # each index read once
    train = {Path(p).stem: Path(p) for p in index.paths("train")}
    trials = frames_run(run / "results/trials", train)
    joint = frames_run(run / "results/fixed", train)
    print(f"== {run}")
    for name, s in {**trials, **joint}.items():
        print(f"  {name:10s} trials {s['trials']:4d} pruned {s['pruned']:4d} failed "
              f"{s['failed']:3d} frames run {100 * float(s['fraction']):5.1f} %  best "
              f"{s['best']:.4g} %")
    bests = [float(s["best"]) for name, s in trials.items()]
    print(f"  median best RTE over training sequences: {np.median(bests):.4g} %")
    fractions = [float(s["fraction"]) for s in trials.values()]
    print(f"  per-sequence studies: frames run {100 * np.mean(fractions):.1f} % (mean), "
          f"joint {100 * float(next(iter(joint.values()))['fraction']):.1f} %")
    cv = json.loads((run / "metrics/surrogate.json").read_text())
    print(f"  surrogate LOSO: MAE {cv['mae']:.4g}, RMSE {cv['rmse']:.4g}, regret "
          f"{cv['regret_mean']:.4g}")
    for seq, c in coverage(run / "results/adaptune.duckdb").items():
        print(f"  coverage {seq}: {c['frames']} frames, {c['groups']} trial sets; distinct "
              f"trials a frame, first third {c['early_trials']:.1f}, last third "
              f"{c['late_trials']:.1f}; rows above the median trial, first third "
              f"{100 * c['early_bad']:.0f} %, last third {100 * c['late_bad']:.0f} %")
    cpu = stage_cpu(run)
    if costs and cpu:
        model_trials = sum(predicted_cpu(s, costs) for s in trials.values())
        model_joint = sum(predicted_cpu(s, costs) for s in joint.values())
        print(f"  CPU, model / measured: trials {model_trials:.0f} / {cpu.get('trials', 0):.0f}"
              f" s, joint {model_joint:.0f} / {cpu.get('fixed', 0):.0f} s")
    if cpu:
        print("  CPU by stage [s]: " + ", ".join(f"{k} {v:.0f}" for k, v in cpu.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--costs", type=Path, default=None)
    args = parser.parse_args()
    costs = json.loads(args.costs.read_text()) if args.costs else None
    for run in args.runs:
        report(run, costs)


if __name__ == "__main__":
    main()
