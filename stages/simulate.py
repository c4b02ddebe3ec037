"""``adaptune simulate``, ``simulate-set`` and ``simulate-kitti-set`` (the dvc stages) and
``plot-world``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from stages.common import compose, dir_option, file_option, params_option

WORLDS = ("cave", "open", "street", "composite")
SENSORS = ("hdl32", "hdl64", "vlp16")


def _choice(flag: str, choices: tuple[str, ...], help: str):  # type: ignore[no-untyped-def]
    return click.option(flag, type=click.Choice(choices), default=choices[0], show_default=True,
                        help=help)


_world_options = compose(
    _choice("--world", WORLDS, "World to generate (street with --kitti-trajectory)."),
    click.option("--seed", type=int, default=0, show_default=True,
                 help="Seed of world, route and sensor noise: same seed, same bytes."),
    click.option("--frames", type=int, default=300, show_default=True,
                 help="Frames (10 Hz)."),
    _choice("--sensor", SENSORS, "hdl32 = Velodyne HDL-32E, hdl64 = HDL-64E (KITTI), "
            "vlp16 = VLP-16."),
    click.option("--segments", default="cave,open,street", show_default=True,
                 help="Composite world: comma-separated segments in driving order."),
    file_option("--kitti-trajectory", required=False,
                help="Drive along a KITTI ground-truth pose file (NN.txt, camera frame) "
                "through a street world generated along it."),
)


def _spec(world: str, seed: int, frames: int, sensor: str, segments: str,
          kitti_trajectory: Path | None, noise: float | None = None,
          dropout: float | None = None,
          motion_distortion: bool = False):  # type: ignore[no-untyped-def]
    """The SimSpec of the ``_world_options`` (and noise / dropout), checked."""
    from pipeline.sim.simulate import SimSpec

    if kitti_trajectory is not None and world == "cave":  # the default: switch to street
        world = "street"
    segs = tuple(s.strip() for s in segments.split(",") if s.strip())
    spec = SimSpec(world, seed, frames, sensor, segs, kitti_trajectory, noise, dropout,
                   motion_distortion)
    spec.check()
    return spec


@click.command()
@_world_options
@click.option("--noise", type=float, default=None, help="Range noise std [m] (default 0.02).")
@click.option(
    "--dropout", type=float, default=None, help="Return dropout probability (default 0.01)."
)
@click.option("--motion-distortion", is_flag=True,
              help="Sweep each scan over 1/rate s from the moving sensor (distorted, as real "
              "scans) and store per-point time; default: instantaneous scans.")
@click.option("--name", default=None, help="Sequence name (default: the file stem of --out).")
@file_option("--out", help="Sequence MCAP to write (atomically).")
def simulate(name: str | None, out: Path, **world: Any) -> None:
    """Ray-cast a simulated world into a sequence MCAP (points, ground truth, labels)."""
    from pipeline.sim.simulate import simulate_sequence

    spec = _spec(**world)
    s = simulate_sequence(spec, out, name=name, progress=True)
    labels = ", ".join(f"{x.label} {x.start}-{x.end}" for x in s.labels)
    click.echo(
        f"{s.path}: {s.frames} frames, {s.points} points, {s.length_m:.0f} m, labels: {labels}",
        err=True,
    )


def _simulate_data_set(params_path: Path | None, out: Path, section_name: str, model: Any,
                       run: Any) -> None:
    """Load ``section_name`` (``model``) and ``base``, run ``run`` into ``out``, summarise."""
    from pipeline.config import BaseSection, load_section

    section = load_section(params_path, section_name, model)
    base = load_section(params_path, "base", BaseSection)
    done = run(section, base.seed, out, progress=sys.stderr.isatty())
    for s in done:
        labels = ", ".join(f"{x.label} {x.start}-{x.end}" for x in s.labels)
        click.echo(f"{s.path}: {s.frames} frames, {s.length_m:.0f} m, {labels}", err=True)
    click.echo(f"{out / 'index.json'}: {len(done)} sequences", err=True)


@click.command("simulate-set")
@params_option
@dir_option("--out", help="Folder for <name>.mcap and index.json (data/sequences).")
def simulate_set(params_path: Path | None, out: Path) -> None:
    """Simulate the toy data set of the params section ``simulate`` (dvc stage)."""
    from pipeline.sim.dataset import SimulateSection, simulate_set

    _simulate_data_set(params_path, out, "simulate", SimulateSection, simulate_set)


@click.command("simulate-kitti-set")
@params_option
@dir_option("--out", help="Folder for <NN>.mcap and index.json (data/kitti_sim).")
def simulate_kitti_set(params_path: Path | None, out: Path) -> None:
    """Simulate the KITTI sequences of the params section ``simulate_kitti`` (dvc stage)."""
    from pipeline.sim.kitti_dataset import SimulateKittiSection, simulate_kitti_set

    _simulate_data_set(params_path, out, "simulate_kitti", SimulateKittiSection,
                       simulate_kitti_set)


@click.command("plot-world")
@_world_options
@click.option("--frame", "scan_frame", type=int, default=None,
              help="Frame whose scan is drawn (default: the middle one).")
@file_option("--out", help="PNG to write.")
def plot_world(scan_frame: int | None, out: Path, **world: Any) -> None:
    """Top-down PNG of a world with its trajectory and one scan."""
    from pipeline.sim.plot import plot_world as plot

    spec = _spec(**world)
    click.echo(f"{plot(spec, out, scan_frame)}: world {spec.world}, seed {spec.seed}", err=True)
