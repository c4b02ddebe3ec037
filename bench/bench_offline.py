"""The offline stages (per-sequence trials and the joint "fixed" study) on a reduced toy
config, without and with the savings of issue 16, in the same run.

Config: two simulated training worlds (cave, street), ``FRAMES`` HDL-32E frames each, ndt,
``ITERATIONS`` trials per sequence and ``JOINT_ITERATIONS`` joint trials, 2 workers (a process
pool), the toy's time limit and L = 25 m. "With the savings" is what params.yaml does by
default: the pruner (``trials.pruning`` defaults) in both stages, and a joint study that starts
from the parameters the per-sequence studies predict best (``fixed.warm_start``) with
``fixed.iterations / trials.iterations`` of the trials' iterations. Reported per setting and
stage: wall time, trials/s, odometry frames run and frames/s (the frames the trials actually
ran, over the wall time), and the quality beside it (the best objective of every study). The
bare-odometry limit: ``adapter.run`` over decoded, warmed scans in one process (best of 3),
times the 2 workers.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

from common import Row, best_of, size

FRAMES = size(350, 8)
ITERATIONS = size(48, 3)
JOINT_ITERATIONS = size(48, 2)
WORKERS = 2
LENGTH_M = size(25.0, 2.0)
WITHOUT, WITH = "without savings", "with savings"


def run() -> list[Row]:
    from pipeline.executor import open_executor
    from pipeline.sim.simulate import SimSpec, simulate_sequence

    with tempfile.TemporaryDirectory() as tmp:
        seqs = [simulate_sequence(SimSpec(world, 1, FRAMES), Path(tmp) / f"{world}_{i}.mcap").path
                for i, world in enumerate(size(("cave", "street"), ("street", "street")))]
        bare_fps = bare_odometry_fps(seqs)
        limit = WORKERS * min(bare_fps)
        rows = [Row(f"ndt bare odometry, {FRAMES} HDL-32E frames (cave, street)",
                    min(bare_fps), "frames/s", f"x{WORKERS} workers = {limit:.0f} frames/s "
                    "(the limit)")]
        figures = {}
        with open_executor(WORKERS) as pool:
            pool.submit(time.sleep, 0).result()
            for label in (WITHOUT, WITH):
                figures[label] = stages(seqs, Path(tmp) / label.replace(" ", "_"),
                                        label == WITH, pool)
        return rows + compare(figures, limit)


def bare_odometry_fps(seqs: list[Path]) -> list[float]:
    """Frames/s of ``adapter.run`` with the default parameters on each decoded sequence."""
    from pipeline.odometry.base import Schedule
    from pipeline.odometry.registry import get_adapter
    from pipeline.sequence import SequenceReader

    adapter = get_adapter("ndt")
    out = []
    for seq in seqs:
        with SequenceReader(seq) as reader:
            scans = list(reader)
        adapter.warm(scans)  # type: ignore[attr-defined]
        schedule = Schedule.constant(adapter.space.defaults(), len(scans))
        out.append(len(scans) / best_of(
            lambda scans=scans, schedule=schedule: adapter.run(scans, schedule), 3))
    return out


def stages(seqs: list[Path], out: Path, savings: bool, pool: object) -> dict[str, Any]:
    """Run the trials and the joint study; their wall time, trials, frames run and quality."""
    from pipeline.config import load_section
    from pipeline.tuning.section import FixedSection, TrialsSection, joint_settings
    from pipeline.tuning.smbo import run_trials, study_adapter
    from pipeline.tuning.warm_start import warm_start_params

    defaults = Path(__file__).resolve().parents[1] / "params.yaml"
    trials = load_section(defaults, "trials", TrialsSection)
    fixed = load_section(defaults, "fixed", FixedSection)
    settings = TrialsSection(algorithm="ndt", iterations=ITERATIONS, workers=WORKERS,
                             length_m=LENGTH_M, time_limit_s=size(600.0, None),
                             pruning=trials.pruning if savings else {"percentile": None})
    joint_iterations = JOINT_ITERATIONS
    if savings:  # the defaults' share of the trials'
        joint_iterations = round(JOINT_ITERATIONS * joint_settings(trials, fixed).iterations
                                 / trials.iterations)
    got: dict[str, Any] = {}
    for stage, joint, iterations in (("trials", False, ITERATIONS),
                                     ("fixed", True, joint_iterations)):
        s = settings.model_copy(update={"iterations": iterations})
        first = (warm_start_params(out / "trials", "ndt", study_adapter(s).space,
                                   fixed.warm_start)
                 if joint and savings and fixed.warm_start else [])
        t0 = time.perf_counter()
        summaries = run_trials(seqs, out / stage, s, seed=0, joint=joint, progress=False,
                               executor=pool, warm_start=first)  # type: ignore[arg-type]
        wall = time.perf_counter() - t0
        got[stage] = (wall, sum(x.trials for x in summaries), frames_run(out / stage),
                      [x.best_objective for x in summaries],
                      sum(x.pruned for x in summaries), len(first))
    return got


def frames_run(out: Path) -> int:
    """Frames in every trajectory a study wrote (a pruned trial's are partial)."""
    import pyarrow.parquet as pq

    return sum(pq.read_metadata(p).num_rows
               for p in (out / "trajectories").glob("*/*/*/trajectory.parquet"))


def compare(figures: dict[str, dict[str, Any]], limit: float) -> list[Row]:
    rows = []
    for stage in ("trials", "fixed"):
        base = figures[WITHOUT][stage]
        for label, got in figures.items():
            wall, trials, frames, best, pruned, warm = got[stage]
            shown = ", ".join(f"{b:.3f}" for b in best)
            ref = (f"{base[0] / wall:.2f}x faster than without" if label == WITH
                   else "the reference")
            how = f"{pruned} of {trials} pruned" + (f", {warm} warm starts" if warm else "")
            rows += [
                Row(f"{stage} {label}: wall time", wall, "s", ref),
                Row(f"{stage} {label}: trials/s ({how})", trials / wall, "trials/s"),
                Row(f"{stage} {label}: odometry frames run", frames, "frames",
                    f"{frames / base[2]:.2f} of without" if label == WITH else ""),
                Row(f"{stage} {label}: odometry frames/s", frames / wall, "frames/s",
                    f"limit {limit:.0f} frames/s"),
                Row(f"{stage} {label}: best objective per study", min(best), "% RTE",
                    f"all: {shown}"),
            ]
    total = {label: sum(got[s][0] for s in ("trials", "fixed")) for label, got in figures.items()}
    rows.append(Row("trials + fixed with savings: wall time", total[WITH], "s",
                    f"{total[WITHOUT]:.1f} s without: {total[WITHOUT] / total[WITH]:.2f}x",
                    "3x (issue 16)"))
    return rows
