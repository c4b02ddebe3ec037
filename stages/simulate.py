"""``adaptune simulate``, ``simulate-set`` and ``simulate-kitti-set`` (the dvc stages) and
``plot-world``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from stages.common import compose, dir_option, file_option, out_option, params_option

WORLDS = ("cave", "open", "street", "composite", "kitti")
SENSORS = ("hdl32", "hdl64", "vlp16")
MOTIONS = ("none", "sweep", "compensated")


def _choice(flag: str, choices: tuple[str, ...], help: str):  # type: ignore[no-untyped-def]
    return click.option(flag, type=click.Choice(choices), default=choices[0], show_default=True,
                        help=help)


_world_options = compose(
    params_option,
    _choice("--world", WORLDS, "World to generate; kitti: the simulated-KITTI world of "
            "--kitti-trajectory."),
    click.option("--seed", type=int, default=0, show_default=True,
                 help="Seed of world, route and sensor noise: same seed, same bytes."),
    click.option("--frames", type=int, default=300, show_default=True,
                 help="Frames (10 Hz; kitti: KITTI's stamps)."),
    click.option("--sensor", type=click.Choice(SENSORS), default=None,
                 help="hdl32 = Velodyne HDL-32E, hdl64 = HDL-64E (KITTI's) [default: the "
                 "params section's: simulate.sensor, or simulate_kitti.sensor for kitti]."),
    click.option("--segments", default="cave,open,street", show_default=True,
                 help="Composite world: comma-separated segments in driving order."),
    file_option("--kitti-trajectory", required=False,
                help="--world kitti: a KITTI ground-truth pose file NN.txt (camera frame; "
                "NN_times.txt beside it gives the stamps); the world of sequence NN."),
    click.option("--start", type=int, default=0, show_default=True,
                 help="--world kitti: frame k of the output is frame START + k of the file."),
    click.option("--motion", type=click.Choice(MOTIONS), default=None,
                 help="none: instantaneous scans; sweep: swept over 1/rate s with per-point "
                 "time; compensated: swept, then moved into the frame at the stamp (KITTI's "
                 "files) [default: the params section's]."),
)


def _spec(params_path: Path | None, world: str, seed: int, frames: int, sensor: str | None,
          segments: str, kitti_trajectory: Path | None, start: int, motion: str | None,
          noise: float | None = None,
          dropout: float | None = None):  # type: ignore[no-untyped-def]
    """The SimSpec of the ``_world_options`` (and noise / dropout), checked; sensor, effects
    and motion from the params section ``simulate`` (``simulate_kitti`` for --world kitti)
    unless given."""
    from pipeline.config import load_section, validate_section
    from pipeline.sim.dataset import SimulateSection
    from pipeline.sim.effects import SensorEffects
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from pipeline.sim.simulate import SimSpec

    name = "simulate_kitti" if world == "kitti" else "simulate"
    section: SimulateSection | SimulateKittiSection = (
        load_section(params_path, name, SimulateKittiSection) if world == "kitti"
        else load_section(params_path, name, SimulateSection))
    given = {k: v for k, v in (("range_noise_m", noise), ("dropout", dropout)) if v is not None}
    effects = validate_section(SensorEffects, f"{name}.effects",
                               section.effects.model_dump() | given)
    segs = tuple(s.strip() for s in segments.split(",") if s.strip())
    spec = SimSpec(world, seed, frames, sensor or section.sensor, segs, effects,
                   motion or section.motion, kitti_trajectory, start,  # type: ignore[arg-type]
                   *([section.world] if isinstance(section, SimulateKittiSection) else []))
    spec.check()
    return spec


@click.command()
@_world_options
@click.option("--noise", type=float, default=None,
              help="Range noise std [m] at short range (default: the params section's).")
@click.option("--dropout", type=float, default=None,
              help="Return dropout probability (default: the params section's).")
@click.option("--name", default=None, help="Sequence name (default: the file stem of --out).")
@out_option(help="Sequence MCAP to write (atomically)")
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
@out_option(help="PNG to write")
def plot_world(scan_frame: int | None, out: Path, **world: Any) -> None:
    """Top-down PNG of a world with its trajectory and one scan."""
    from pipeline.sim.plot import plot_world as plot

    spec = _spec(**world)
    click.echo(f"{plot(spec, out, scan_frame)}: world {spec.world}, seed {spec.seed}", err=True)
