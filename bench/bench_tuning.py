"""SMBO tuner figures: trials/s with 1 and 2 workers, and the pipeline's overhead around a trial.

Sequence: a simulated street world (``pipeline.sim``), 300 HDL-32E frames of ~54k points, the
length of a toy training sequence; adapter ``ndt`` at its baseline.
- bare odometry: ``adapter.run`` over scans already in memory, after ``adapter.warm`` (which a
  worker runs once per study; its cost is its own row) (best of 3);
- one trial: ``run_trial`` as a process-pool worker runs it (with the time limit: in the
  worker's trial server, scans decoded once: run + check + RTE + write Parquet, result back
  through a socket; best of 3, warm);
  overhead = (trial - bare) / bare;
- trials/s: ``run_trials`` of 8 trials on an already started process pool of W workers;
- studies side by side: ``run_trials`` of STUDIES studies (the sequence under as many names) of
  8 trials on 2 workers, side by side (one single-process pool a study, each study warmed once:
  ``pipeline.tuning.smbo.side_by_side``) against the reference in the same run, one shared pool
  of 2 workers running the studies one after another (every worker warms every study); both
  timings include starting the pools, the trials tables must be equal.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common import Row, best_of, size

N_FRAMES = size(300, 8)
LENGTH_M = size(25.0, 2.0)
ITERATIONS = size(8, 2)
STUDIES = 4


def run() -> list[Row]:
    from pipeline.executor import open_executor
    from pipeline.odometry.base import Schedule
    from pipeline.odometry.registry import get_adapter
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import SimSpec, simulate_sequence
    from pipeline.tuning.job import TrialJob
    from pipeline.tuning.section import TrialsSection
    from pipeline.tuning.smbo import run_trials
    from pipeline.tuning.worker import run_trial

    with tempfile.TemporaryDirectory() as tmp:
        seq = simulate_sequence(SimSpec("street", 1, N_FRAMES), Path(tmp) / "street.mcap").path
        adapter = get_adapter("ndt")
        params = adapter.space.defaults()
        with SequenceReader(seq) as r:
            scans = list(r)
        t0 = time.perf_counter()
        adapter.warm(scans)  # what a worker does once per study (the trial below has it too)
        warm_s = time.perf_counter() - t0
        bare_s = best_of(
            lambda: adapter.run(scans, Schedule.constant(params, len(scans))), repeat=3
        )

        def job(limit: float | None) -> TrialJob:
            return TrialJob(
                adapter="ndt",
                algorithm="ndt",
                sequences=(("street", str(seq)),),
                trial=0,
                seed=0,
                params=params,
                out_dir=str(Path(tmp) / "one"),
                length_m=LENGTH_M,
                penalty_pct=100.0,
                jump_limit_m=5.0,
                time_limit_s=limit,
            )

        assert run_trial(job(600.0)).status == "ok"  # starts the trial server
        child_s = best_of(lambda: run_trial(job(600.0)), repeat=3)
        inproc_s = best_of(lambda: run_trial(job(None)), repeat=3)

        rates = {}
        for workers in (1, 2):
            settings = TrialsSection(
                algorithm="ndt", iterations=ITERATIONS, workers=workers, length_m=LENGTH_M,
                time_limit_s=size(600.0, None),
                pruning={"percentile": 50.0},  # as measured before the default became off
            )
            with open_executor(workers) as ex:
                ex.submit(time.sleep, 0).result()
                t0 = time.perf_counter()
                run_trials(
                    [seq], Path(tmp) / f"w{workers}", settings, seed=0, progress=False, executor=ex
                )
                rates[workers] = ITERATIONS / (time.perf_counter() - t0)
        side_s, shared_s = studies_side_by_side(Path(tmp), seq)

    fps = N_FRAMES / bare_s
    return [
        Row(f"ndt bare odometry, {N_FRAMES} HDL-32E frames", bare_s, "s", f"{fps:.0f} frames/s"),
        Row("ndt warm-up (source clouds), once per worker and study", warm_s, "s",
            f"{100 * warm_s / bare_s:.0f} % of one bare run"),
        Row(
            "pipeline overhead around a trial (child process, read, check, score, write)",
            100 * (child_s - bare_s) / bare_s,
            "% of bare run",
            f"trial {child_s:.3f} s",
            "<= 5 %",
        ),
        Row(
            "pipeline overhead around a trial (in-process, no time limit)",
            100 * (inproc_s - bare_s) / bare_s,
            "% of bare run",
            f"trial {inproc_s:.3f} s",
            "<= 5 %",
        ),
        Row(f"ndt trials/s, 1 worker ({N_FRAMES} frames a trial)", rates[1], "trials/s"),
        Row(
            f"ndt trials/s, 2 workers ({N_FRAMES} frames a trial)",
            rates[2],
            "trials/s",
            f"{rates[2] / rates[1]:.2f}x of 1 worker (2 shared cores)",
        ),
        Row(
            f"{STUDIES} studies of {ITERATIONS} trials ({N_FRAMES} frames), 2 workers side by side",
            side_s,
            "s",
            f"one shared pool {shared_s:.1f} s (same run): x{side_s / shared_s:.2f}",
            "<= the shared pool",
        ),
    ]


def studies_side_by_side(tmp: Path, seq: Path) -> tuple[float, float]:
    """Wall times [s] of STUDIES studies (``seq`` linked under as many names) on 2 workers:
    side by side, and on one shared pool (given to ``run_trials``: one study at a time); both
    with the pools' start. The two runs' trials tables are checked equal."""
    import os

    import pyarrow.parquet as pq

    from pipeline.executor import open_executor
    from pipeline.tuning.section import TrialsSection
    from pipeline.tuning.smbo import run_trials
    from pipeline.tuning.table import trials_path

    paths = []
    for i in range(STUDIES):
        path = tmp / "studies" / f"s{i}.mcap"
        path.parent.mkdir(exist_ok=True)
        os.link(seq, path)
        paths.append(path)
    settings = TrialsSection(algorithm="ndt", iterations=ITERATIONS, workers=2, length_m=LENGTH_M,
                             time_limit_s=600.0)
    t0 = time.perf_counter()
    run_trials(paths, tmp / "side", settings, seed=0, progress=False)
    side_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    with open_executor(2) as ex:
        run_trials(paths, tmp / "shared", settings, seed=0, progress=False, executor=ex)
    shared_s = time.perf_counter() - t0
    for path in paths:
        tables = [pq.read_table(trials_path(tmp / out, "ndt", path.stem))
                  for out in ("side", "shared")]
        assert tables[0].equals(tables[1]), f"{path.stem}: side by side changed the trials"
    return side_s, shared_s
