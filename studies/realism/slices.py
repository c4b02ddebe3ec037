"""The scans of a slice of KITTI: real (the odometry benchmark's files) and simulated (the
simulated-KITTI world of the sequence along the same ground-truth poses)."""

from __future__ import annotations

from pathlib import Path

from pipeline.sequence import Scan
from pipeline.sim.kitti_dataset import SimulateKittiSection


def real_slice(kitti_root: Path, sequence: str, first: int, last: int) -> list[Scan]:
    """Frames ``first`` .. ``last`` (inclusive) of KITTI ``sequence`` under ``kitti_root``
    (sequences/NN/velodyne, poses/NN.txt) with their ground truth (T_world_lidar)."""
    from pipeline.sources.kitti import KittiSource

    source = KittiSource(kitti_root, sequence, first, last)
    return [Scan(k, f.stamp_ns, f.points_lidar, f.T_world_lidar)
            for k, f in enumerate(source.frames())]


def replica_seed(replica: int, sequence: str) -> int:
    """The world seed of the comparison's simulated replica ``replica`` of ``sequence``."""
    from pipeline.sim.simulate import derive_seed

    return derive_seed(replica, sequence)


def simulated_slice(trajectories: Path, sequence: str, first: int, last: int,
                    section: SimulateKittiSection, seed: int) -> list[Scan]:
    """The same frames simulated: the simulated-KITTI world of ``sequence`` (seed ``seed``)
    along ``trajectories``/NN.txt, scanned as the ``simulate_kitti`` section configures."""
    from pipeline.sim.kitti_dataset import kitti_sensor
    from pipeline.sim.kitti_world import build_kitti_world
    from pipeline.sim.simulate import iter_scans

    world = build_kitti_world(trajectories / f"{sequence}.txt", sequence, seed, first, last,
                              section.world)
    return list(iter_scans(world, kitti_sensor(section), seed,
                           motion=section.motion))
