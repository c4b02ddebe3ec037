"""How much can any NDT selector gain on the dev worlds? (issue 12; docs/results/noise-floor.md)

Not a `make bench` module (about 80 minutes on 2 cores): ``.venv/bin/python bench/headroom.py
[--cache DIR]``. On the 8 worlds of the generalization suite's **dev** root it
1. runs NDT with every set of a 12 x 10 grid over its two parameters (resolution 1-10 m,
   keyframe interval 0-10 m) and the toy's fixed parameters, each constant over the world;
2. reports the constant sets that do best over the worlds, as adaptive / min(baseline, fixed)
   would score them (median, worst, win rate): what a selector that always picks one set can do;
3. runs the *class oracle*: every frame gets, for its true environment label (cave, open,
   street: known to the oracle, not to a selector), the grid set whose RTE over that label's
   frames was best on the **other** seven worlds (mean log ratio to each world's median set),
   held for a second as the selector holds its choice; scored as the suite scores adaptive;
4. reports the hindsight oracle per label (the best grid set per label on the world itself,
   its frames' errors stitched from the constant runs): an upper bound no selector reaches.

Per-frame errors of every run are cached as .npy under ``--cache`` (default
``$XDG_CACHE_HOME/adaptune/headroom``), so a second call only prints.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))  # common.py

from common import TOY_FIXED_NDT

RESOLUTION_M = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0)
KEYFRAME_M = (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0)
BASELINE = (4.0, 4.0)
FIXED = (TOY_FIXED_NDT["resolution"], TOY_FIXED_NDT["keyframe_interval"])
SETS = [*itertools.product(RESOLUTION_M, KEYFRAME_M), FIXED]
WORLDS = 8
LENGTH_M = 25.0
Set = tuple[float, float]


def _key(s: Set) -> str:
    return f"{s[0]:.4f}_{s[1]:.4f}"


def per_frame_errors(path: Path, values: np.ndarray, out: Path) -> np.ndarray:
    """Per-start-frame RTE [%] (N,) of NDT run with per-frame (N, 2) parameter ``values``
    (100 where the run failed), cached at ``out``."""
    from pipeline.errors import OdometryError
    from pipeline.metrics.rte import per_frame_rte
    from pipeline.odometry import get_adapter, run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.sequence import SequenceReader

    if out.is_file():
        return np.load(out)
    with SequenceReader(path) as reader:
        gt = reader.require_ground_truth("to score against")
    schedule = Schedule(np.arange(len(gt), dtype=np.int32),
                        {"resolution": values[:, 0].copy(),
                         "keyframe_interval": values[:, 1].copy()})
    try:
        t_err, _ = per_frame_rte(gt, run_sequence(get_adapter("ndt"), path, schedule)
                                 .T_world_lidar, LENGTH_M)
    except OdometryError:
        t_err = np.full(len(gt), 100.0)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.save(out, t_err)
    return t_err


def _constant(job: tuple[Path, Set, Path]) -> np.ndarray:
    path, s, cache = job
    with_n = _frames(path)
    return per_frame_errors(path, np.tile(np.array(s), (with_n, 1)), cache / f"{_key(s)}.npy")


def _frames(path: Path) -> int:
    from pipeline.sequence import SequenceReader

    with SequenceReader(path) as reader:
        return len(reader)


def simulate_worlds(cache: Path) -> dict[str, tuple[Path, np.ndarray]]:
    """The dev worlds' MCAPs (simulated once into ``cache``) and their frame labels."""
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import simulate_sequence
    from studies.generalization.suite import GeneralizeSection, world_of

    section = GeneralizeSection(suite="dev")
    out = {}
    for i in range(WORLDS):
        world = world_of(section, "dev", i)
        path = cache / "worlds" / f"{world.name}.mcap"
        if not path.is_file():
            path.parent.mkdir(parents=True, exist_ok=True)
            simulate_sequence(world.spec, path, name=world.name)
        with SequenceReader(path) as reader:
            labels = np.array([reader.info.label_of(f) or "" for f in range(len(reader))])
        out[world.name] = (path, labels)
    return out


def class_oracle_values(name: str, grids: dict[str, dict[Set, np.ndarray]],
                        labels: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 2) parameters of world ``name``: per frame the set chosen for its label from the
    other worlds (module docstring, step 3), held for 10 frames (1 s)."""
    def label_rte(w: str, s: Set, lab: str) -> float:
        return float(np.nanmean(grids[w][s][labels[w] == lab]))

    choice = {}
    for lab in sorted(set(labels[name])):
        others = [w for w in grids if w != name and lab in set(labels[w])]
        score = {s: np.mean([np.log(label_rte(w, s, lab)
                                    / np.median([label_rte(w, q, lab) for q in SETS]))
                             for w in others]) for s in SETS}
        choice[lab] = min(score, key=lambda s: score[s])
    lab = labels[name]
    return np.array([choice[lab[(i // 10) * 10]] for i in range(len(lab))])


def summary(ratios: list[float]) -> str:
    r = np.array(ratios)
    return f"median {np.median(r):.2f}, worst {r.max():.2f}, win rate {np.mean(r < 1):.0%}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    home = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    parser.add_argument("--cache", type=Path, default=home / "adaptune" / "headroom")
    cache = parser.parse_args().cache
    worlds = simulate_worlds(cache)
    jobs = [(path, s, cache / "grid" / name) for name, (path, _) in worlds.items() for s in SETS]
    with ProcessPoolExecutor(2) as pool:
        errors = list(pool.map(_constant, jobs, chunksize=4))
    grids = {name: dict(zip(SETS, errors[i * len(SETS):(i + 1) * len(SETS)], strict=True))
             for i, name in enumerate(worlds)}
    labels = {name: lab for name, (_, lab) in worlds.items()}
    rte = {n: {s: float(np.nanmean(t)) for s, t in g.items()} for n, g in grids.items()}
    best_fixed = {n: min(r[BASELINE], r[FIXED]) for n, r in rte.items()}

    print(f"dev worlds {', '.join(worlds)}; ratio = RTE / min(baseline, fixed) per world")
    constant = sorted(SETS, key=lambda s: np.median([rte[n][s] / best_fixed[n] for n in rte]))
    for s in constant[:3]:
        print(f"constant {s}: {summary([rte[n][s] / best_fixed[n] for n in rte])}")
    robust = min(SETS, key=lambda s: max(rte[n][s] / best_fixed[n] for n in rte))
    print(f"constant {robust} (smallest worst world): "
          f"{summary([rte[n][robust] / best_fixed[n] for n in rte])}")
    with ProcessPoolExecutor(2) as pool:
        oracle = list(pool.map(per_frame_errors, [worlds[n][0] for n in worlds],
                               [class_oracle_values(n, grids, labels) for n in worlds],
                               [cache / "oracle" / f"{n}.npy" for n in worlds]))
    ratios = [float(np.nanmean(t)) / best_fixed[n] for n, t in zip(worlds, oracle, strict=True)]
    print("class oracle (true labels, sets from the other worlds), per world: "
          + " ".join(f"{r:.2f}" for r in ratios) + f"; {summary(ratios)}")
    hindsight = []
    for n, g in grids.items():
        stitched = np.full(len(labels[n]), np.nan)
        for lab in set(labels[n]):
            m = labels[n] == lab
            best = min(SETS, key=lambda s, m=m: float(np.nanmean(g[s][m])))
            stitched[m] = g[best][m]
        hindsight.append(float(np.nanmean(stitched)) / best_fixed[n])
    print("hindsight per label (stitched), per world: "
          + " ".join(f"{r:.2f}" for r in hindsight) + f"; {summary(hindsight)}")


if __name__ == "__main__":
    main()
