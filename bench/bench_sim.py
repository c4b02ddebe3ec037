"""Simulation speed beside one odometry step, and the phenomenon sweep (issue 3).

Rows:
- HDL-32E scans per second of the default scan (params ``simulate``: sensor effects, swept),
  world built once, cave and street; reference: one odometry step (ndt and gicp adapters, two
  consecutive simulated scans). HDL-64E scans per second in simulated KITTI (params
  ``simulate_kitti``: KITTI's unit and car, compensated sweeps, traffic).
- Sweep: mean translational RTE [%] (25 m segments) of the ndt and gicp keyframe adapters over
  keyframe interval x resolution / max correspondence distance, in a cave and a street world.
  The worlds make the paper's phenomenon real when a large keyframe interval corrupts the cave
  run while it beats small intervals in the street.
Environment: ADAPTUNE_BENCH_SIM_SEEDS (default "1"), ADAPTUNE_BENCH_SIM_FRAMES (default 300).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from common import Row, best_of, size

SWEEP = {
    "ndt": [
        dict(keyframe_interval=kf, resolution=r)
        for kf in size((0.0, 1.0, 2.0, 10.0), (1.0, 10.0)) for r in size((2.0, 4.0), (2.0,))
    ],
    "gicp": [
        dict(keyframe_interval=kf, max_correspondence_distance=d)
        for kf in size((1.0, 2.0, 10.0), (1.0, 10.0))
        for d in size((1.0, 4.0), (1.0,))
    ],
}
LENGTH_M = size(25.0, 2.0)
"""The RTE's sub-trajectory length [m]."""


def run() -> list[Row]:
    return speed_rows() + sweep_rows()


def speed_rows() -> list[Row]:
    """Scans a second of the default scan (what ``simulate`` writes: the params sections'
    sensor effects and motion), the world and its ray caster built once: HDL-32E in a cave and
    a street (``simulate``), HDL-64E in simulated KITTI (``simulate_kitti``, sequence 04, where
    the test data has its trajectory)."""
    from pipeline.config import load_section
    from pipeline.odometry.registry import get_adapter
    from pipeline.sim.dataset import SimulateSection
    from pipeline.sim.simulate import SimSpec, iter_scans, make_world

    params = Path(__file__).resolve().parents[1] / "params.yaml"
    toy = load_section(params, "simulate", SimulateSection)
    rows = []
    for world in size(("cave", "street"), ("street",)):
        spec = SimSpec(world, 1, size(40, 3), "hdl32", effects=toy.effects, motion=toy.motion)
        w = make_world(spec)
        t = _scan_cost(w, spec.sensor_model(), spec.motion)
        scans = list(iter_scans(w, spec.sensor_model(), 1, size(range(20, 22), range(0, 2))))
        steps = []
        for algo in ("ndt", "gicp"):
            ad = get_adapter(algo)
            steps.append(f"{algo} step {1000 * _step_cost(ad, scans):.1f} ms")
        rows.append(Row(f"simulate HDL-32E scans/s ({world}, {toy.motion}, "
                        f"{len(scans[0].xyz)} pts)", 1.0 / t, "scans/s",
                        "; ".join(steps) + f" (scan {1000 * t:.1f} ms)", ">= 50 scans/s"))
    kitti = _kitti_spec(params)
    if kitti is not None:
        w = make_world(kitti)
        t = _scan_cost(w, kitti.sensor_model(), kitti.motion)
        rows.append(Row(f"simulate HDL-64E scans/s (simulated KITTI 04, {kitti.motion})",
                        1.0 / t, "scans/s", f"scan {1000 * t:.1f} ms", "no slower than before"))
    return rows


def _kitti_spec(params: Path) -> object:
    """The SimSpec of simulated KITTI 04, frames 0-39, at the ``simulate_kitti`` section's
    sensor, effects, world and motion; None without the test data."""
    from common import data_root

    from pipeline.config import load_section
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from pipeline.sim.simulate import SimSpec

    path = data_root() / "kitti_trajectories" / "04.txt"
    if not path.is_file():
        return None
    section = load_section(params, "simulate_kitti", SimulateKittiSection)
    return SimSpec("kitti", 1, size(40, 3), section.sensor, effects=section.effects,
                   motion=section.motion, kitti_trajectory=path, kitti_world=section.world)


def _scan_cost(world: object, sensor: object, motion: str) -> float:
    """Best wall time [s] of one default scan of ``world`` (caster built once)."""
    from pipeline.sim.raycast import Raycaster
    from pipeline.sim.simulate import scan_frame

    w = world
    caster = Raycaster(w.vertices, w.triangles, sensor, w.materials, w.seed)  # type: ignore[attr-defined]
    scan_frame(caster, w, 1, 0, motion)  # type: ignore[arg-type]  # builds the BVH
    k = iter(range(10**9))
    frames = w.frames - 1  # type: ignore[attr-defined]
    return best_of(lambda: scan_frame(caster, w, 1, next(k) % frames, motion),  # type: ignore[arg-type]
                   repeat=5, number=10)


def _step_cost(adapter: object, scans: list) -> float:
    """Best wall time [s] of one odometry step on the second of two consecutive scans."""
    best = float("inf")
    for _ in range(5):
        odom = adapter.start(adapter.space.defaults())  # type: ignore[attr-defined]
        odom.step(scans[0].xyz, scans[0].stamp_ns)
        t0 = time.perf_counter()
        odom.step(scans[1].xyz, scans[1].stamp_ns)
        best = min(best, time.perf_counter() - t0)
    return best


def sweep_rows() -> list[Row]:
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.odometry.base import Schedule
    from pipeline.odometry.registry import get_adapter
    from pipeline.sim.simulate import SimSpec, iter_scans, make_world

    seeds = [int(s) for s in os.environ.get("ADAPTUNE_BENCH_SIM_SEEDS", "1").split(",")]
    frames = int(os.environ.get("ADAPTUNE_BENCH_SIM_FRAMES", size("300", "20")))
    rows: list[Row] = []
    for world in size(("cave", "street"), ("street",)):
        for seed in seeds:
            spec = SimSpec(world, seed, frames)
            w = make_world(spec)
            scans = list(iter_scans(w, spec.sensor_model(), seed, motion=spec.motion))
            gt = w.poses.T_world_lidar
            length = float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())
            for algo, grid in SWEEP.items():
                results = []
                for params in grid:
                    ad = get_adapter(algo)
                    t0 = time.perf_counter()
                    traj = ad.run(scans, Schedule.constant(ad.space.validate(params), len(scans)))
                    ms = 1000 * (time.perf_counter() - t0) / len(scans)
                    results.append((params, mean_rte_pct(gt, traj.T_world_lidar, LENGTH_M), ms))
                rows += _rows(world, seed, algo, length, results)
    return rows


def _rows(
    world: str, seed: int, algo: str, length: float, results: list[tuple[dict, float, float]]
) -> list[Row]:
    out = []
    best = min(results, key=lambda r: r[1])
    for params, rte, ms in results:
        label = " ".join(f"{_short(k)}={v:g}" for k, v in params.items())
        out.append(
            Row(
                f"sweep {world}#{seed} ({length:.0f} m) {algo} {label}",
                rte,
                "% RTE",
                f"{ms:.0f} ms/step" + ("  <- best" if params is best[0] else ""),
                "cave: kf 10 worse" if world == "cave" else "street: kf 10 better",
            )
        )
    small = [
        r for p, r, _ in results if p["keyframe_interval"] <= (2.0 if world == "cave" else 1.0)
    ]
    large = [r for p, r, _ in results if p["keyframe_interval"] >= 10.0]
    ratio = (min(large) / min(small)) if world == "cave" else (min(small) / min(large))
    what = "best kf10 / best kf<=2" if world == "cave" else "best kf<=1 / best kf10"
    out.append(
        Row(
            f"phenomenon {world}#{seed} {algo}: {what}",
            ratio,
            "x",
            f"best: {' '.join(f'{_short(k)}={v:g}' for k, v in best[0].items())} ({best[1]:.2f} %)",
            "> 1",
        )
    )
    return out


def _short(name: str) -> str:
    return {"keyframe_interval": "kf", "resolution": "res", "max_correspondence_distance": "mcd"}[
        name
    ]
