"""How chaotic is each odometry in its parameters? (the noise floor of the generalization suite;
docs/results/noise-floor.md)

On worlds of the generalization suite's **dev** root (the ``generalize`` section of
``--params``, the repository's params.yaml by default), every adapter runs its defaults (and the
toy reproduction's trained algorithm also its fixed set, read from the evaluate stage's record,
``records/evaluation.json``: ``params.fixed``) once as they are and ``--replicas`` times with
every parameter moved by at most 0.5 % (``pipeline.evaluate.runs.run_replicas``: the same
factors the ``evaluate`` and ``generalize`` stages' replicas use). Per world the coefficient of
variation of the runs' mean RTE (L: the section's, or ``--length-m``); over the worlds its
median, and over ordered pairs of runs of one setting on one world the fraction whose ratio
exceeds the suite's worst-world target (``generalize.targets.worst``): how often a selector
exactly as good as a fixed setting would miss that target by chance.

``python experiments/noise_floor.py [--worlds 0,3] [--replicas 4] [--algorithms
ndt,gicp,kiss_icp]``: the default, dev worlds 0 and 3 (HDL-32E, HDL-64E), takes a few minutes;
the figures of docs/results/noise-floor.md: ``--worlds 0,1,2,3,4,5,6,7 --replicas 8
--algorithms ndt`` (about an hour on 2 cores). The worlds are simulated in a temporary folder.
``--frames N`` cuts every world to its first N frames of one street segment (a quick look, no
figure of the page).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from studies.generalization.suite import GeneralizeSection
from studies.generalization.summary import cv, pair_ratios

REPO = Path(__file__).resolve().parents[1]
RECORD = REPO / "records" / "evaluation.json"
"""The toy reproduction's committed evaluate record: the fixed set it ran with."""


def toy_fixed(record: Path) -> dict[str, dict[str, float]]:
    """{algorithm: its fixed set} of the evaluate stage's ``record`` (``algorithm`` and
    ``params.fixed``: the joint study's parameters that the evaluate stage ran as fixed)."""
    if not record.is_file():
        raise SystemExit(f"{record}: no such file (the evaluate stage's record, with the fixed "
                         "set the toy reproduction ran; `make repro` writes it)")
    data = json.loads(record.read_text())
    fixed = data.get("params", {}).get("fixed") if isinstance(data, dict) else None
    if not isinstance(fixed, dict) or not fixed or "algorithm" not in data:
        raise SystemExit(f"{record}: no 'algorithm' and 'params.fixed' (the fixed set the "
                         "evaluate stage ran with)")
    return {str(data["algorithm"]): {str(k): float(v) for k, v in fixed.items()}}


def runs_of(algorithm: str, params: dict[str, float], path: Path, gt: np.ndarray,
            replicas: int, length_m: float) -> list[float]:
    """Mean RTE [%] (L = ``length_m``) of the nominal run and of ``replicas`` perturbed runs
    (NaN: failed), with the evaluate code's replicas (``pipeline.evaluate.runs.run_replicas``)."""
    from pipeline.errors import OdometryError
    from pipeline.evaluate.runs import run_replicas
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.odometry import get_adapter, run_sequence

    adapter = get_adapter(algorithm)
    section = EvaluateSection(length_m=length_m, replicas=replicas)  # its 0.5 % replica_scale
    try:
        out = [mean_rte_pct(gt, run_sequence(adapter, path, params).T_world_lidar, length_m)]
    except OdometryError:
        out = [float("nan")]
    runs = run_replicas(adapter, path, gt, params, section)
    return out + [float("nan") if r.t_err_pct is None else float(np.nanmean(r.t_err_pct))
                  for r in runs]


def chance_above(runs: list[list[float]], target: float) -> float:
    """Fraction of ordered pairs of distinct runs of one setting with a ratio above the
    worst-world ``target`` (``studies.generalization.summary.pair_ratios``)."""
    pairs = pair_ratios(runs)
    return float(np.mean(pairs > target)) if len(pairs) else float("nan")


def measure(section: GeneralizeSection, worlds: list[int], algorithms: list[str],
            replicas: int, length_m: float, fixed: dict[str, dict[str, float]],
            frames: int | None = None) -> dict[str, list[list[float]]]:
    """{algorithm: the runs (nominal, then the replicas) of every setting on every dev world
    of ``section``}."""
    from pipeline.odometry import get_adapter
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import simulate_sequence
    from studies.generalization.suite import generalization_world

    runs: dict[str, list[list[float]]] = {a: [] for a in algorithms}
    with tempfile.TemporaryDirectory() as tmp:
        for i in worlds:
            world = generalization_world(section, "dev", i)
            path = Path(tmp) / f"{world.name}.mcap"
            spec = world.spec if frames is None else replace(world.spec, frames=frames,
                                                             segments=("street",))
            simulate_sequence(spec, path, name=world.name)
            with SequenceReader(path) as reader:
                gt = reader.require_ground_truth("to score against")
            for algorithm in algorithms:
                settings = [get_adapter(algorithm).space.defaults()]
                settings += [fixed[algorithm]] if algorithm in fixed else []
                for params in settings:
                    runs[algorithm].append(runs_of(algorithm, params, path, gt, replicas,
                                                   length_m))
            path.unlink()
    return runs


def report(runs: dict[str, list[list[float]]], worlds: list[int], replicas: int,
           target: float) -> list[str]:
    """One line per algorithm: the median CV over worlds x settings (with its range) and the
    share of pairs of runs above the worst-world ``target``."""
    names = ", ".join(f"dev_{i:02d}" for i in worlds)
    lines = []
    for algorithm, per_world in runs.items():
        cvs = [v for v in map(cv, per_world) if np.isfinite(v)] or [float("nan")]
        lines.append(f"{algorithm}: RTE spread under <= 0.5 % parameter moves ({names}; "
                     f"{replicas} replicas): median CV over {len(per_world)} worlds x settings "
                     f"{np.median(cvs):.3f} (range {min(cvs):.2f}-{max(cvs):.2f}); pairs of "
                     f"runs of one setting whose ratio exceeds {target:g}: "
                     f"{100.0 * chance_above(per_world, target):.1f} %")
    return lines


def main(argv: list[str] | None = None) -> None:
    from pipeline.config import load_section

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default="0,3", help="dev worlds, by index")
    parser.add_argument("--replicas", type=int, default=4)
    parser.add_argument("--algorithms", default="ndt,gicp,kiss_icp")
    parser.add_argument("--length-m", type=float, default=None,
                        help="the RTE length L [default: the generalize section's]")
    parser.add_argument("--frames", type=int, default=None,
                        help="cut every world to N frames of one street segment")
    parser.add_argument("--params", type=Path, default=REPO / "params.yaml",
                        help="the params file whose generalize section draws the worlds")
    parser.add_argument("--record", type=Path, default=RECORD,
                        help="the evaluate stage's record holding the toy's fixed set")
    args = parser.parse_args(argv)
    section = load_section(args.params, "generalize", GeneralizeSection).model_copy(
        update={"suite": "dev"})
    worlds = [int(i) for i in args.worlds.split(",")]
    runs = measure(section, worlds, args.algorithms.split(","), args.replicas,
                   args.length_m or section.length_m, toy_fixed(args.record), args.frames)
    for line in report(runs, worlds, args.replicas, section.targets.worst):
        print(line)


if __name__ == "__main__":
    main()
