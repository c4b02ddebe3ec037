"""``adaptune realism``: real KITTI slices against simulated KITTI along the same poses."""

from __future__ import annotations

from pathlib import Path

import click

from stages.common import dir_option, params_option


@click.command()
@params_option
@dir_option("--kitti-root", help="KITTI odometry root (sequences/NN/velodyne, poses/NN.txt), "
            "e.g. ../shared/data/kitti_mini/dataset.")
@dir_option("--trajectories", help="Folder of the full ground-truth files NN.txt (the "
            "simulated worlds are built along them), e.g. ../shared/data/kitti_trajectories.")
@click.option("--replicas", type=int, default=3, show_default=True,
              help="Simulated worlds (seeds) per slice.")
@click.option("--slice", "slices", multiple=True, metavar="NN:FIRST:LAST",
              help="A slice to compare (repeatable) [default: 01, 04, 06, 10, frames 0-9].")
@dir_option("--out", help="Folder for realism.json, realism.md and realism.png.")
def realism(params_path: Path | None, kitti_root: Path, trajectories: Path, replicas: int,
            slices: tuple[str, ...], out: Path) -> None:
    """Compare scan statistics and frame-to-frame odometry errors (GICP, KISS-ICP at their
    defaults) of real KITTI slices with the same frames simulated (params section
    ``simulate_kitti``)."""
    from pipeline.config import load_section
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from studies.realism.compare import SLICES, TARGET_RATIO, parse_slice, run_realism
    from studies.realism.report import write_realism

    section = load_section(params_path, "simulate_kitti", SimulateKittiSection)
    chosen = tuple(parse_slice(s) for s in slices) or SLICES
    result = run_realism(kitti_root, trajectories, section, replicas, chosen)
    paths = write_realism(result, out)
    within = result.within_target()
    click.echo(f"{paths[1]}: {sum(within.values())} of {len(within)} figures within "
               f"x{TARGET_RATIO:g} (simulated / real)", err=True)
