"""How the rungs of successive halving change the fraction of frames run and the full KITTI
protocol's cost (issue 33; docs/kitti.md, "What the told lag and the rungs do").

For every ``eta:rungs`` given, runs bench/bench_kitti.py's halving study with those rungs (256
NDT proposals on sequence 00's first 150 frames, 16 workers' settings, or ``--workers``: the
proposals lag 2 W - 1 trials, the rungs rank every earlier trial; ADAPTUNE_BENCH_HALVING_TRIALS
sets another budget) and prints its fraction of frames, promotion rates and waiting at the
rungs, and the core-hours of the full protocol at the paper's budget
(``bench_kitti.protocol_cost``) for every adapter of ``--costs`` (JSON {algorithm: {env:
bench_kitti.Cost fields}}, as ``experiments/fidelity.py --measure`` writes it). Whole
trials do not depend on the rungs and are printed once. Quality is not measured here: a
setting that saves more is not thereby a good one (docs/kitti.md gives the gates).

``python experiments/promotion.py 3:3 3:4 4:3 --costs costs.json``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(1, str(HERE / "bench"))


def main() -> None:
    import bench_kitti
    from common import data_root

    from pipeline.tuning.pruning import HalvingSection

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("settings", nargs="+", help="eta:rungs, e.g. 3:4")
    parser.add_argument("--costs", type=Path, required=True)
    parser.add_argument("--workers", type=int, default=16,
                        help="the workers the study is set for (its proposals lag 2 W - 1 "
                        "trials; 1 worker: 1)")
    args = parser.parse_args()
    costs = {name: {env: bench_kitti.Cost(**c) for env, c in by_env.items()}
             for name, by_env in json.loads(args.costs.read_text()).items()}
    trajectories = data_root() / "kitti_trajectories"
    drives = bench_kitti.kitti_drives(trajectories)
    frames = 150
    for name, cost in costs.items():
        whole = bench_kitti.protocol_cost(drives, cost, bench_kitti.Promotion([], 1, 0, 0), False)
        print(f"whole trials, {name}: {whole.core_s / 3600:.1f} core-h, "
              f"{whole.wall_s / 3600:.1f} h on {bench_kitti.WORKERS} workers")
    for setting in args.settings:
        eta, rungs = (int(x) for x in setting.split(":"))
        halving = HalvingSection(eta=eta, rungs=rungs)
        with tempfile.TemporaryDirectory() as tmp:
            promotion = bench_kitti.halving_promotion(trajectories, frames, drives, Path(tmp),
                                                      halving, args.workers)
        rates = ", ".join(f"{100 * r:.0f} %" for r in promotion.rates)
        line = (f"eta {eta}, rungs {rungs} (first {100 * halving.fractions()[0]:.1f} %), "
                f"{promotion.trials} trials, {args.workers} worker(s)' proposals: "
                f"frames run {100 * promotion.fraction:.1f} %, going on {rates}, waiting at "
                f"the rungs {100 * promotion.waiting:.1f} % of the work")
        for name, cost in costs.items():
            p = bench_kitti.protocol_cost(drives, cost, promotion, True,
                                          bench_kitti.Plan(halving=halving))
            line += f"; {name} {p.core_s / 3600:.1f} core-h, {p.wall_s / 3600:.1f} h"
        print(line, flush=True)


if __name__ == "__main__":
    main()
