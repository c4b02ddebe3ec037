"""Simulation speed beside one odometry step, and the phenomenon sweep (issue 3).

Rows:
- HDL-32E scans per second (ray casting + noise, world built once), cave and street;
  reference: one odometry step (ndt and gicp adapters, two consecutive simulated scans).
- Sweep: mean translational RTE [%] (25 m segments) of the ndt and gicp keyframe adapters over
  keyframe interval x resolution / max correspondence distance, in a cave and a street world.
  The worlds make the paper's phenomenon real when a large keyframe interval corrupts the cave
  run while it beats small intervals in the street.
Environment: ADAPTUNE_BENCH_SIM_SEEDS (default "1"), ADAPTUNE_BENCH_SIM_FRAMES (default 300).
"""

from __future__ import annotations

import os
import time

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
    from pipeline.odometry.registry import get_adapter
    from pipeline.sim.raycast import Raycaster
    from pipeline.sim.simulate import SimSpec, iter_scans, make_world

    rows = []
    for world in size(("cave", "street"), ("street",)):
        spec = SimSpec(world, 1, size(40, 3))
        w = make_world(spec)
        caster = Raycaster(w.vertices, w.triangles, spec.sensor_model())
        caster.scan(w.poses.T_world_lidar[0], np.random.default_rng(0))  # builds the BVH
        poses = w.poses.T_world_lidar
        k = iter(range(10**9))
        t = best_of(
            lambda c=caster, p=poses, k=k: c.scan(p[next(k) % len(p)], np.random.default_rng(0)),
            repeat=5,
            number=10,
        )
        scans = list(iter_scans(w, spec.sensor_model(), 1, size(range(20, 22), range(0, 2))))
        steps = []
        for algo in ("ndt", "gicp"):
            ad = get_adapter(algo)
            steps.append(f"{algo} step {1000 * _step_cost(ad, scans):.1f} ms")
        rows.append(
            Row(
                f"simulate HDL-32E scans/s ({world}, {len(scans[0].xyz)} pts)",
                1.0 / t,
                "scans/s",
                "; ".join(steps) + f" (scan {1000 * t:.1f} ms)",
                ">= 50 scans/s",
            )
        )
    return rows


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
            scans = list(iter_scans(w, spec.sensor_model(), seed))
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
