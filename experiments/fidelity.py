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
- the cost check of bench/bench_kitti.py's model (a run of simulated KITTI; docs/kitti.md, "The
  cost model against a measured run"), with per-frame CPU costs (``--costs`` JSON:
  {algorithm: {env: bench_kitti.Cost fields}}, written by ``--measure`` as the bench measures
  them: 20 frames of one sequence per environment, the defaults and 3 sampled sets, read from
  the MCAP and over cached scans):
  - measured: the seconds the trials tables and the evaluation record give for every trial
    and every evaluated run (wall time: the CPU time of the single-threaded odometry when
    every stage ran ``workers: 1`` on an otherwise idle core, as the check's runs do; not the
    CPU by stage of timing.log, which does not count every process of a stage: its fixed
    stage shows seconds of CPU for minutes of joint trials);
  - the model on the frames the run ran (frames run x the per-frame cost of the frame's
    environment, cached where the study fit the worker's scan cache: checks the per-frame
    costs);
  - the model alone (``bench_kitti.protocol_cost`` on the run's windows, budgets, L, rungs and
    one worker, with promotion rates p_r: the run's own, pooled over its per-sequence studies,
    or ``--rates``, e.g. the bench's: checks the fraction of frames too).

``python experiments/fidelity.py RUN [RUN ...] [--costs costs.json [--measure]]
[--rates 0.46,0.76]``
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(1, str(Path(__file__).resolve().parents[1] / "bench"))

from pipeline.sequence import SequenceReader
from pipeline.tuning.layout import JOINT_SEQUENCE, trajectory_path, trials_files


def frames_run(out: Path, sequences: dict[str, Path]) -> dict[str, dict[str, object]]:
    """Per study of the trials folder ``out``: its trials, the frames they ran per sequence
    and environment, the fraction of frames run, and the frames of its sequences by
    environment."""
    import pyarrow.parquet as pq

    from pipeline.trajectory import read_trajectory

    info = {name: _labels(path) for name, path in sequences.items()}
    studies: dict[str, dict[str, object]] = {}
    for algorithm, study, table in trials_files(out):
        t = pq.read_table(table).to_pydict()
        names = list(sequences) if study == JOINT_SEQUENCE else [study]
        ran_env: dict[str, int] = {}
        ran = total = 0
        by_trial: list[int] = []
        for trial, status in zip(t["trial"], t["status"], strict=True):
            by_trial.append(ran)
            for name in names:
                labels = info[name]
                path = trajectory_path(out, algorithm, name, trial)
                unrun = 0 if status == "pruned" else len(labels)  # a rung of whole sequences
                n = len(read_trajectory(path)) if path.is_file() else unrun
                for env in labels[:n]:
                    ran_env[env] = ran_env.get(env, 0) + 1
                ran += n
                total += len(labels)
            by_trial[-1] = ran - by_trial[-1]
        studies[study] = {"trials": len(t["trial"]), "pruned": t["status"].count("pruned"),
                          "wall_s": float(sum(t["wall_time_s"])),
                          "failed": t["status"].count("failed"), "fraction": ran / total,
                          "frames_by_env": ran_env, "frames_by_trial": by_trial,
                          "frames_by_env_whole": {env: sum(info[n].count(env) for n in names)
                                                  for env in {e for n in names for e in info[n]}},
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


Costs = dict[str, Any]
"""Environment -> bench_kitti.Cost of one adapter."""


def predicted_cpu(study: dict[str, object], costs: Costs, cached: bool) -> float:
    """CPU seconds of a study's trials by the model: frames run x the per-frame cost of a
    sampled set (over cached scans where the study's sequences fit the worker's cache: ``cached``;
    then decoding them once too)."""
    frames = study["frames_by_env"]
    length = study["frames_by_env_whole"]
    assert isinstance(frames, dict) and isinstance(length, dict)
    per = {env: (c.cpu_cached if cached else c.cpu_sampled) for env, c in costs.items()}
    decode = sum(n * costs[env].cpu_decode for env, n in length.items()) if cached else 0.0
    return sum(n * per[env] for env, n in frames.items()) + decode


def fits_cache(sequences: list[Path]) -> bool:
    """Whether one worker of this machine kept ``sequences`` decoded (a run with ``workers:
    1``: pipeline.tuning.worker)."""
    from pipeline.tuning.worker import decoded_bytes, scan_cache_limit_bytes

    return sum(decoded_bytes(str(p)) for p in sequences) <= scan_cache_limit_bytes()


def measure_costs(algorithm: str) -> dict[str, dict[str, float]]:
    """bench_kitti.Cost of ``algorithm`` per environment as ``python bench/run.py kitti``
    measures it (bench_kitti.simulate and adapter_cost; its environment variables apply), as
    JSON."""
    import dataclasses
    import os
    import tempfile

    import bench_kitti
    from common import data_root

    frames = int(os.environ.get("ADAPTUNE_BENCH_KITTI_FRAMES", "20"))
    samples = int(os.environ.get("ADAPTUNE_BENCH_KITTI_SAMPLES", "3"))
    with tempfile.TemporaryDirectory() as tmp:
        paths, _ = bench_kitti.simulate(data_root() / "kitti_trajectories", frames, Path(tmp))
        costs = bench_kitti.environment_costs(algorithm, paths, samples)
    return {env: dataclasses.asdict(c) for env, c in costs.items()}


def evaluated(run: Path, sequences: dict[str, Path], costs: Costs) -> tuple[float, float]:
    """(measured seconds, model CPU seconds) of the adaptive and evaluate stages' runs of
    records/evaluation.json: baseline at the defaults' cost, fixed and adaptive at the
    sampled sets' (read from the MCAP)."""
    record = json.loads((run / "records/evaluation.json").read_text())["sequences"]
    measured = model = 0.0
    for name, seq in record.items():
        labels = _labels(sequences[name])
        for setting, wall in seq["wall_time_s"].items():
            measured += float(wall)
            model += sum(costs[env].cpu_default if setting == "baseline"
                         else costs[env].cpu_sampled for env in labels)
    return measured, model


def model_alone(run: Path, costs: Costs, rates: list[float] | None,
                studies: dict[str, dict[str, object]]) -> tuple[Any, list[float]]:
    """bench_kitti.protocol_cost on the run's windows of simulated KITTI, budgets, L, rungs,
    one worker and this machine's memory (params.yaml of the run), with promotion ``rates``
    (None: the run's own, pooled over its per-sequence studies: ``run_rates``); and the rates."""
    import bench_kitti
    import yaml
    from common import data_root

    from pipeline.executor import machine_memory_bytes
    from pipeline.tuning.pruning import HalvingSection

    params = yaml.safe_load((run / "params.yaml").read_text())
    sim, trials, fixed = params["simulate_kitti"], params["trials"], params["fixed"]
    full = bench_kitti.kitti_drives(data_root() / "kitti_trajectories")
    drives = {name: bench_kitti.Drive(full[name].environments[a:b + 1],
                                      full[name].distance_m[a:b + 1] - full[name].distance_m[a])
              for name, a, b in sim["windows"]}
    halving = HalvingSection(**trials["halving"])
    joint = HalvingSection(**fixed["halving"]) if fixed.get("halving") else halving
    length_m = float(params["base"]["length_m"])
    plan = bench_kitti.Plan(train=tuple(sim["train"]), iterations=trials["iterations"],
                            joint_iterations=fixed["iterations"] or trials["iterations"],
                            length_m=length_m, halving=halving, joint_halving=joint, workers=1,
                            memory_bytes=machine_memory_bytes() or bench_kitti.MEMORY_BYTES)
    if rates is None:
        rates = run_rates({s: drives[s] for s in studies}, studies, halving, length_m)
    promotion = bench_kitti.Promotion(rates, math.nan, 0, 0.0)
    halved = (fixed.get("fidelity") or trials["fidelity"]) == "halving"
    return bench_kitti.protocol_cost(drives, costs, promotion, halved, plan), rates


def run_rates(drives: dict[str, Any], studies: dict[str, dict[str, object]],
              halving: Any, length_m: float) -> list[float]:
    """p_r of a run: of the trials of its per-sequence studies that reached rung r where r is
    checked (a segment of ``length_m`` has ended by its last frame), the share that went on."""
    from pipeline.tuning.pruning import rungs

    reached = [0] * (halving.rungs - 1)
    went_on = [0] * (halving.rungs - 1)
    for name, study in studies.items():
        drive = drives[name]
        for r, point in enumerate(rungs([drive.frames], halving)):
            end = point.frames[0]
            if drive.distance_m[end] <= length_m:
                continue
            ran = study["frames_by_trial"]
            assert isinstance(ran, list)
            reached[r] += sum(n > end for n in ran)
            went_on[r] += sum(n > end + 1 for n in ran)
    return [w / n if n else 1.0 for w, n in zip(went_on, reached, strict=True)]


def cost_check(run: Path, sequences: dict[str, Path], studies: dict[str, dict[str, object]],
               joint: dict[str, dict[str, object]], costs: Costs,
               rates: list[float] | None) -> None:
    """Print the cost model against the run (module docstring)."""
    train = [sequences[name] for name in studies]
    measured = {"studies": sum(float(s["wall_s"]) for s in studies.values()),  # type: ignore[arg-type]
                "joint": sum(float(s["wall_s"]) for s in joint.values())}  # type: ignore[arg-type]
    on_run = {"studies": sum(predicted_cpu(s, costs, fits_cache([sequences[name]]))
                             for name, s in studies.items()),
              "joint": sum(predicted_cpu(s, costs, fits_cache(train)) for s in joint.values())}
    measured["evaluate"], on_run["evaluate"] = evaluated(run, sequences, costs)
    p, used = model_alone(run, costs, rates, studies)
    alone = {"studies": p.studies_s, "joint": p.joint_s, "evaluate": p.evaluate_s}
    source = "given" if rates is not None else "the run's own, per-sequence studies"
    print(f"  model alone with promotion rates {', '.join(f'{r:.2f}' for r in used)} "
          f"({source})")
    parts = {part: (measured[part], on_run[part], alone[part]) for part in measured}
    parts["total"] = (sum(measured.values()), sum(on_run.values()), sum(alone.values()))
    print("  cost [min]    measured  model on the frames run  model alone")
    for part, (m, r, a) in parts.items():
        print(f"  {part:12s} {m / 60:8.2f}  {r / 60:14.2f} (x{r / m:4.2f})  {a / 60:7.2f} "
              f"(x{a / m:4.2f})")


def report(run: Path, costs: dict[str, dict[str, dict[str, float]]] | None,
           rates: list[float] | None) -> None:
    from pipeline.sequence_index import read_index

    folders = (run / "data/kitti_sim", run / "data/kitti", run / "data/sequences")
    indexes = (read_index(p) for p in folders if (p / "index.json").is_file())
    index = next(i for i in indexes if i.splits.get("train"))  # each index read once
    train = {Path(p).stem: Path(p) for p in index.paths("train")}
    every = {Path(p).stem: Path(p) for split, names in index.splits.items() if names
             for p in index.paths(split)}  # a split may be declared empty
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
    if not (run / "metrics/surrogate.json").is_file():  # the verdict's: per sensor
        print("  (no metrics/surrogate.json, results/adaptune.duckdb: studies only)")
    else:
        cv = json.loads((run / "metrics/surrogate.json").read_text())
        print(f"  surrogate LOSO: MAE {cv['mae']:.4g}, RMSE {cv['rmse']:.4g}, regret "
              f"{cv['regret_mean']:.4g}")
        for seq, c in coverage(run / "results/adaptune.duckdb").items():
            print(f"  coverage {seq}: {c['frames']} frames, {c['groups']} trial sets; distinct "
                  f"trials a frame, first third {c['early_trials']:.1f}, last third "
                  f"{c['late_trials']:.1f}; rows above the median trial, first third "
                  f"{100 * c['early_bad']:.0f} %, last third {100 * c['late_bad']:.0f} %")
        algorithm = str(json.loads((run / "records/evaluation.json").read_text())["algorithm"])
        if costs and algorithm in costs:
            import bench_kitti

            cost_check(run, every, trials, joint,
                       {env: bench_kitti.Cost(**c) for env, c in costs[algorithm].items()}, rates)
    cpu = stage_cpu(run)
    if cpu:
        print("  CPU by stage [s]: " + ", ".join(f"{k} {v:.0f}" for k, v in cpu.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--costs", type=Path, default=None,
                        help="per-frame costs JSON {algorithm: {env: bench_kitti.Cost fields}}")
    parser.add_argument("--measure", action="store_true",
                        help="measure the costs of the runs' algorithms missing in --costs first")
    parser.add_argument("--rates", default=None,
                        help="promotion rates per rung, comma-separated (the bench's)")
    args = parser.parse_args()
    costs = json.loads(args.costs.read_text()) if args.costs and args.costs.is_file() else {}
    if args.measure and args.costs:
        for run in args.runs:
            name = json.loads((run / "records/evaluation.json").read_text())["algorithm"]
            if name not in costs:
                costs[name] = measure_costs(name)
                args.costs.write_text(json.dumps(costs, indent=1))
    rates = [float(r) for r in args.rates.split(",")] if args.rates else None
    for run in args.runs:
        report(run, costs, rates)


if __name__ == "__main__":
    main()
