"""Do the step errors add up? Real KITTI slices against simulated ones
(docs/results/kitti-sim.md, "What the simulated windows lack").

``python experiments/realism_drift.py [--params params.yaml] [--replicas 3] [--data DIR]
[--slice NN:FIRST:LAST ...] [--algorithms gicp,kiss_icp]``: every kitti_mini slice of the
comparison (``studies.realism.compare.SLICES``: frames 0-9 of 01, 04, 06 and 10, under
``--data``: ``ADAPTUNE_TEST_DATA`` or ../shared/data) and its simulated replicas (the
``simulate_kitti`` section of ``--params``, world seed ``replica_seed(r, SEQ)`` for replica r,
as the comparison seeds them), run by GICP and KISS-ICP at their defaults. Per side, in
percent of the distance travelled (the ground truth's path over the slice):

- **step**: the median step error ||t(E)|| over the median step length (the comparison's figure
  in other units);
- **bias**: the norm of the mean step error vector, the part every step shares;
- **drift**: the end-to-end error over the whole slice, the relative pose error of frames
  0 and 9 (as the KITTI devkit's t_err takes it over a segment), over the path length.

Errors of one size that do not add up (random steps) give a drift near step / sqrt(steps);
a shared bias adds in full. The simulated side is scored against its exact ground truth.
Slice 10 creeps (0.19 m a step): its percentages divide by under 2 m of road.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np


def drift_figures(T_gt: np.ndarray, T_est: np.ndarray) -> tuple[float, float, float]:
    """(step, bias, drift) in % of the distance (module docstring) of an estimate T_est
    (N, 4, 4) against the ground truth T_gt (N, 4, 4), both T_world_lidar."""
    from pipeline.metrics.trajectory_error import rpe_error_poses
    from studies.realism.registration import step_error_poses

    steps_m = np.linalg.norm(np.diff(T_gt[:, :3, 3], axis=0), axis=1)
    t_m = step_error_poses(T_gt, T_est)[:, :3, 3]
    step = float(np.median(np.linalg.norm(t_m, axis=1)) / np.median(steps_m))
    bias = float(np.linalg.norm(t_m.mean(axis=0)) / np.median(steps_m))
    whole = rpe_error_poses(T_gt, T_est, np.array([0]), np.array([len(T_gt) - 1]))[0, :3, 3]
    drift = float(np.linalg.norm(whole) / steps_m.sum())
    return 100.0 * step, 100.0 * bias, 100.0 * drift


def data_root() -> Path:
    """The real KITTI data (kitti_mini/, kitti_trajectories/): ``ADAPTUNE_TEST_DATA``, or
    ../shared/data beside the repository."""
    env = os.environ.get("ADAPTUNE_TEST_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"


def main(argv: list[str] | None = None) -> None:
    from pipeline.config import load_section
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from studies.realism.compare import ALGORITHMS, SLICES, parse_slice
    from studies.realism.registration import odometry_trajectory
    from studies.realism.slices import real_slice, replica_seed, simulated_slice

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--params", type=Path, default=Path("params.yaml"))
    parser.add_argument("--replicas", type=int, default=3)
    parser.add_argument("--data", type=Path, default=None,
                        help="the folder of kitti_mini/ and kitti_trajectories/")
    parser.add_argument("--slice", dest="slices", action="append", metavar="NN:FIRST:LAST",
                        help="a slice (repeatable) [default: the comparison's]")
    parser.add_argument("--algorithms", default=",".join(ALGORITHMS))
    args = parser.parse_args(argv)
    section = load_section(args.params, "simulate_kitti", SimulateKittiSection)
    root = args.data or data_root()
    slices = [parse_slice(s) for s in args.slices] if args.slices else SLICES
    print("| slice | algorithm | side | step [%] | bias [%] | drift [%] |")
    print("|---|---|---|---|---|---|")
    for seq, first, last in slices:
        sides = [("real", real_slice(root / "kitti_mini" / "dataset", seq, first, last))]
        sides += [(f"sim {r}", simulated_slice(root / "kitti_trajectories", seq, first, last,
                                               section, replica_seed(r, seq)))
                  for r in range(args.replicas)]
        for algorithm in args.algorithms.split(","):
            for name, scans in sides:
                step, bias, drift = drift_figures(
                    *odometry_trajectory(algorithm, scans, f"{name} {seq}"))
                print(f"| {seq} {first}-{last} | {algorithm} | {name} | {step:.2f} | "
                      f"{bias:.2f} | {drift:.2f} |", flush=True)


if __name__ == "__main__":
    main()
