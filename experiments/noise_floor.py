"""How chaotic is each odometry in its parameters? (issue 12: the noise floor of the suite)

On worlds of the generalization suite's **dev** root, every adapter runs its defaults (and
NDT also the toy's fixed parameters) once as they are and ``NOISE_REPLICAS`` times with every
parameter moved by at most 0.5 % (``pipeline.evaluate.replicas``: the same factors the
``evaluate`` and ``generalize`` stages' replicas use). Per world the coefficient of variation
of the runs' mean RTE (L = 25 m); over the worlds its median, and over ordered pairs of runs
of one setting on one world the fraction whose ratio exceeds 1.05, the issue's worst-world
target: how often a selector exactly as good as a fixed setting would miss that target by
chance.

Default: dev worlds 0 and 3 (HDL-32E, HDL-64E), 4 replicas (a few minutes). The figures of
docs/results/noise-floor.md: ``NOISE_WORLDS=8 NOISE_ALGORITHMS=ndt,gicp python bench/run.py
noise`` (about an hour on 2 cores; the worlds are simulated here, in a temporary folder).
"""

from __future__ import annotations

import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))  # common.py

from common import TOY_FIXED_NDT, Row, size

from studies.generalization.summary import TARGET_WORST, cv, pair_ratios

TOY_FIXED = {"ndt": TOY_FIXED_NDT}
LENGTH_M = size(25.0, 2.0)


def _worlds() -> list[int]:
    n = os.environ.get("NOISE_WORLDS")
    return list(range(int(n))) if n else size([0, 3], [0])


def _algorithms() -> list[str]:
    return os.environ.get("NOISE_ALGORITHMS", "ndt,gicp,kiss_icp").split(",")


def runs_of(algorithm: str, params: dict[str, float], path: Path, gt: np.ndarray,
            replicas: int) -> list[float]:
    """Mean RTE [%] (L = 25 m) of the nominal run and of ``replicas`` perturbed runs (NaN:
    failed), with the evaluate code's replicas (``pipeline.evaluate.runs.run_replicas``)."""
    from pipeline.errors import OdometryError
    from pipeline.evaluate.runs import run_replicas
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.odometry import get_adapter, run_sequence

    adapter = get_adapter(algorithm)
    section = EvaluateSection(length_m=LENGTH_M, replicas=replicas)  # its 0.5 % replica_scale
    try:
        out = [mean_rte_pct(gt, run_sequence(adapter, path, params).T_world_lidar, LENGTH_M)]
    except OdometryError:
        out = [float("nan")]
    runs = run_replicas(adapter, path, gt, params, section)
    return out + [float("nan") if r.t_err_pct is None else float(np.nanmean(r.t_err_pct))
                  for r in runs]


def chance_above(runs: list[list[float]]) -> float:
    """Fraction of ordered pairs of distinct runs of one setting with a ratio above the
    worst-world target (``studies.generalization.summary.pair_ratios``)."""
    pairs = pair_ratios(runs)
    return float(np.mean(pairs > TARGET_WORST)) if len(pairs) else float("nan")


def run() -> list[Row]:
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import simulate_sequence
    from studies.generalization.suite import GeneralizeSection, world_of

    replicas = int(os.environ.get("NOISE_REPLICAS", size("4", "1")))
    section = GeneralizeSection(suite="dev")
    runs: dict[str, list[list[float]]] = {a: [] for a in _algorithms()}
    with tempfile.TemporaryDirectory() as tmp:
        for i in _worlds():
            world = world_of(section, "dev", i)
            path = Path(tmp) / f"{world.name}.mcap"
            spec = size(world.spec, replace(world.spec, frames=10, segments=("street",)))
            simulate_sequence(spec, path, name=world.name)
            with SequenceReader(path) as reader:
                gt = reader.require_ground_truth("to score against")
            for algorithm in runs:
                from pipeline.odometry import get_adapter

                settings = [get_adapter(algorithm).space.defaults()]
                settings += [TOY_FIXED[algorithm]] if algorithm in TOY_FIXED else []
                for params in settings:
                    runs[algorithm].append(runs_of(algorithm, params, path, gt, replicas))
            path.unlink()
    rows = []
    names = ", ".join(f"dev_{i:02d}" for i in _worlds())
    for algorithm, per_world in runs.items():
        cvs = [v for v in map(cv, per_world) if np.isfinite(v)] or [float("nan")]
        rows.append(Row(f"{algorithm}: RTE spread under <= 0.5 % parameter moves, median CV "
                        f"over worlds x settings ({names}; {replicas} replicas)",
                        float(np.median(cvs)), "",
                        f"range {min(cvs):.2f}-{max(cvs):.2f}", "reported"))
        rows.append(Row(f"{algorithm}: pairs of runs of one setting whose ratio exceeds "
                        f"{TARGET_WORST}", 100.0 * chance_above(per_world), "%", "",
                        "reported (issue 12's worst-world target)"))
    return rows


if __name__ == "__main__":
    from common import format_table

    print(format_table(run()))
