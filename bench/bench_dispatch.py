"""What the pinned CPU dispatch costs (docs/design.md, "Same numbers on every machine").

Each stage command of a small pipeline (two simulated HDL-32E worlds of 60 frames: simulate,
descriptors, an NDT study of 8 trials, rte, surrogate, select) and one GICP and one KISS-ICP run
of a world, timed as whole ``adaptune`` processes in the CPU time they and their children use
(the child processes' rusage: far less noisy than wall time on a shared machine), pinned
(portable, the default) against ``ADAPTUNE_CPU_DISPATCH=native`` (every library picks its code
for this CPU), both in the same run, alternating, the best of ``REPEAT``. A row is portable /
native of one command.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml
from common import Row, size, smoke

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
ADAPTUNE = str(Path(sys.executable).with_name("adaptune"))
REPEAT = size(3, 1)

STEPS = {
    "simulate-set": ["simulate-set", "--out", "seq"],
    "descriptors": ["descriptors", "--sequences", "seq", "--out", "d.parquet", "--environment",
                    "e.parquet", "--pca", "pca"],
    "trials (ndt)": ["trials", "--sequences", "seq", "--out", "trials"],
    "rte": ["rte", "--sequences", "seq", "--trials", "trials", "--descriptors", "d.parquet",
            "--environment", "e.parquet", "--db", "results.duckdb"],
    "surrogate": ["surrogate", "--db", "results.duckdb", "--pca", "pca", "--out", "model",
                  "--trials", "trials"],
    "select": ["select", "model", "seq/street_0.mcap", "--out", "schedule.parquet"],
    "run gicp": ["run", "--algorithm", "gicp", "seq/street_0.mcap", "--out", "gicp.parquet"],
    "run kiss_icp": ["run", "--algorithm", "kiss_icp", "seq/street_0.mcap", "--out",
                     "kiss.parquet"],
}
"""The commands timed, in order (each reads what the ones before wrote); a smoke run times the
first only."""


def params() -> dict:
    """params.yaml with two HDL-32E worlds, an 8-trial NDT study each, L = 10 m."""
    p = yaml.safe_load((REPO / "params.yaml").read_text())
    frames = size(60, 10)
    p["base"]["length_m"] = size(10.0, 2.0)
    p["simulate"].update(train={"street": 1, "cave": 1}, train_frames=frames,
                         validation_count=0, workers=1)
    p["descriptors"].update(workers=1)
    p["trials"].update(iterations=size(8, 2), workers=1, startup_trials=2)
    return p


def cpu_seconds(args: list[str], cwd: Path, env: dict[str, str]) -> float:
    """CPU time [s] (user + system) of ``adaptune ARGS`` and every process it waited for."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([ADAPTUNE, *args], cwd=cwd, env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run() -> list[Row]:
    from pipeline.dispatch import unpinned_environment

    portable = {k: v for k, v in os.environ.items() if k != "ADAPTUNE_CPU_DISPATCH"}
    native = unpinned_environment(os.environ)
    steps = dict(list(STEPS.items())[:size(len(STEPS), 1)])
    best: dict[tuple[str, str], float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(REPEAT):
            for mode, env in (("portable", portable), ("native", native)):
                folder = Path(tmp) / f"{mode}{r}"
                folder.mkdir()
                (folder / "params.yaml").write_text(yaml.safe_dump(params(), sort_keys=False))
                for name, args in steps.items():
                    t = cpu_seconds(args, folder, env)
                    best[name, mode] = min(best.get((name, mode), float("inf")), t)
    rows = [Row(f"pinned dispatch: {name}, CPU time portable / native",
                best[name, "portable"] / best[name, "native"], "x",
                f"native {best[name, 'native']:.2f} s", "") for name in steps]
    total = {m: sum(best[n, m] for n in steps) for m in ("portable", "native")}
    rows.append(Row("pinned dispatch: the whole small pipeline, CPU time portable / native",
                    total["portable"] / total["native"], "x",
                    f"native {total['native']:.1f} s" + (" (smoke)" if smoke() else ""),
                    ""))
    return rows
