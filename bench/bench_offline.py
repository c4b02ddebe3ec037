"""The offline stages (per-sequence trials and the joint "fixed" study) on a reduced toy
config, without and with the pruner, in the same run (issue 16).

Config: two simulated training worlds (cave, street), ``FRAMES`` HDL-32E frames each, ndt,
``ITERATIONS`` trials per sequence and ``JOINT_ITERATIONS`` joint trials, 2 workers (a process
pool), the toy's time limit and L = 25 m. Reported per setting: wall time of each stage,
trials/s, odometry frames/s (the frames the trials actually ran, over the wall time), and the
quality beside it (the best objective of every study). The bare-odometry limit: ``adapter.run``
over decoded, warmed scans in one process (best of 3), times the 2 workers.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common import Row, best_of

FRAMES = 350
ITERATIONS = 32
JOINT_ITERATIONS = 16
WORKERS = 2
LENGTH_M = 25.0


def run() -> list[Row]:
    from pipeline.odometry.base import Schedule
    from pipeline.odometry.registry import get_adapter
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import SimSpec, simulate_sequence
    from pipeline.tuning.smbo import TrialsSection, open_executor

    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        seqs = [simulate_sequence(SimSpec(world, 1, FRAMES), Path(tmp) / f"{world}_0.mcap").path
                for world in ("cave", "street")]
        adapter = get_adapter("ndt")
        bare_fps = []
        for seq in seqs:
            with SequenceReader(seq) as reader:
                scans = list(reader)
            adapter.warm(scans)  # type: ignore[attr-defined]
            schedule = Schedule.constant(adapter.space.defaults(), len(scans))
            bare_fps.append(len(scans) / best_of(
                lambda scans=scans, schedule=schedule: adapter.run(scans, schedule), 3))
        limit = WORKERS * min(bare_fps)
        rows.append(Row(f"ndt bare odometry, {FRAMES} HDL-32E frames (cave, street)",
                        min(bare_fps), "frames/s", f"x{WORKERS} workers = {limit:.0f} frames/s "
                        "(the limit)"))
        figures = {}
        with open_executor(WORKERS) as pool:
            pool.submit(time.sleep, 0).result()
            for label, percentile in (("without pruning", None), ("with pruning", 50.0)):
                settings = TrialsSection(algorithm="ndt", iterations=ITERATIONS, workers=WORKERS,
                                         length_m=LENGTH_M, time_limit_s=600.0,
                                         pruning={"percentile": percentile})
                figures[label] = stages(seqs, Path(tmp) / label.replace(" ", "_"), settings,
                                        pool)
        rows += compare(figures, limit)
    return rows


def stages(seqs: list[Path], out: Path, settings: object, pool: object) -> dict[str, object]:
    """Run the trials and the joint study; their wall time, trials, frames run and quality."""
    from pipeline.tuning.smbo import run_trials

    got: dict[str, object] = {}
    for stage, joint, iterations in (("trials", False, ITERATIONS),
                                     ("fixed", True, JOINT_ITERATIONS)):
        s = settings.model_copy(update={"iterations": iterations})  # type: ignore[attr-defined]
        t0 = time.perf_counter()
        summaries = run_trials(seqs, out / stage, s, seed=0, joint=joint, progress=False,
                               executor=pool)  # type: ignore[arg-type]
        wall = time.perf_counter() - t0
        got[stage] = (wall, sum(x.trials for x in summaries), frames_run(out / stage),
                      [x.best_objective for x in summaries],
                      sum(x.pruned for x in summaries))
    return got


def frames_run(out: Path) -> int:
    """Frames in every trajectory a study wrote (a pruned trial's are partial)."""
    import pyarrow.parquet as pq

    return sum(pq.read_metadata(p).num_rows
               for p in (out / "trajectories").glob("*/*/*/trajectory.parquet"))


def compare(figures: dict[str, dict[str, object]], limit: float) -> list[Row]:
    rows = []
    for stage in ("trials", "fixed"):
        base = figures["without pruning"][stage]
        for label, got in figures.items():
            wall, trials, frames, best, pruned = got[stage]  # type: ignore[misc]
            shown = ", ".join(f"{b:.3f}" for b in best)
            ref = (f"{base[0] / wall:.2f}x faster than without" if got is not figures[
                "without pruning"] else "the reference")  # type: ignore[index]
            rows += [
                Row(f"{stage} {label}: wall time", wall, "s", ref),
                Row(f"{stage} {label}: trials/s ({pruned} of {trials} pruned)",
                    trials / wall, "trials/s"),
                Row(f"{stage} {label}: odometry frames/s", frames / wall, "frames/s",
                    f"limit {limit:.0f} frames/s"),
                Row(f"{stage} {label}: best objective per study", min(best), "% RTE",
                    f"all: {shown}"),
            ]
    return rows
