"""Where a slice's frame-to-frame error lives, per axis, real against simulated (issue 30;
docs/results/realism.md, "Probes of GICP's miss on the highway 01").

``python experiments/realism_axes.py SEQ [--algorithm gicp] [--params params.yaml]
[--replicas 3]``: the real kitti_mini slice SEQ (frames 0-9, ``ADAPTUNE_TEST_DATA`` or
../shared/data) and its simulated replicas (the ``simulate_kitti`` section of ``--params``,
world seed ``replica_seed(r, SEQ)`` for replica r, as the comparison seeds them), run by the
algorithm at its defaults; per side the step errors E (``studies.realism.registration``) split into
the lidar frame's axes (x forward, y left, z up): the mean and the median |component| [cm],
and the median ||t(E)|| [cm]. Exact ground truth on the simulated side (no ground-truth error
added).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))


def main() -> None:
    from common import data_root

    from pipeline.config import load_section
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from studies.realism.compare import SLICES
    from studies.realism.registration import odometry_step_errors
    from studies.realism.slices import real_slice, replica_seed, simulated_slice

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", choices=[s for s, _, _ in SLICES])
    parser.add_argument("--algorithm", default="gicp")
    parser.add_argument("--params", type=Path, default=Path("params.yaml"))
    parser.add_argument("--replicas", type=int, default=3)
    args = parser.parse_args()
    section = load_section(args.params, "simulate_kitti", SimulateKittiSection)
    first, last = next((a, b) for s, a, b in SLICES if s == args.sequence)
    root = data_root()
    sides = [("real", real_slice(root / "kitti_mini" / "dataset", args.sequence, first, last))]
    sides += [(f"sim {r}", simulated_slice(root / "kitti_trajectories", args.sequence, first,
                                           last, section, replica_seed(r, args.sequence)))
              for r in range(args.replicas)]
    print(f"{args.algorithm} on {args.sequence} {first}-{last}: step error t(E) [cm], lidar axes")
    print("| side | mean x / y / z | median abs x / y / z | median norm |\n|---|---|---|---|")
    for name, scans in sides:
        t_cm = 100.0 * odometry_step_errors(args.algorithm, scans, name)[:, :3, 3]
        mean, med = t_cm.mean(0), np.median(np.abs(t_cm), 0)
        print(f"| {name} | {' / '.join(f'{v:.2f}' for v in mean)} | "
              f"{' / '.join(f'{v:.2f}' for v in med)} | "
              f"{np.median(np.linalg.norm(t_cm, axis=1)):.2f} |")


if __name__ == "__main__":
    main()
