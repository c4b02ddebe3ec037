"""What the full KITTI protocol costs (issue 15 item 3), from the per-frame cost of every
in-process adapter on simulated KITTI (docs/kitti.md, "What the full protocol costs").

Scans: simulated KITTI (``pipeline.sim.kitti_dataset``, HDL-64E, ~125k points a scan), the
first FRAMES frames of one sequence per environment: 07 urban, 00 residential, 04 rural,
01 highway. Every adapter runs each of them through ``run_sequence`` (MCAP decoding included:
full KITTI sequences exceed a trial worker's scan cache, so every trial decodes its MCAP), once
with its defaults (the baseline) and with SAMPLES parameter sets drawn uniformly from its search
space (what an SMBO trial costs on average). The figure is CPU time per frame (the process and
its decoding thread), the core-seconds the estimate adds up; the wall time per frame on this
shared machine is beside it.

The estimate weights the environments by their share of KITTI's frames (the simulated-KITTI
schedules, ``pipeline.sim.kitti_world.SCHEDULES``), per sequence, and counts the odometry runs
of the protocol (frame counts n_s from ``kitti_trajectories``: 23,201 frames, 14,136 of them in
00-05; I = J = 256):

    core-s = I * sum_{s in 00-05} n_s c_s  +  J * sum_{s in 00-05} n_s c_s  +  3 * sum_s n_s d_s
    wall(N) = ceil(I / N) * sum_{s in 00-05} n_s c_s  +  ceil(J / N) * sum_{s in 00-05} n_s c_s
              + 3 * sum_s n_s d_s

c_s: CPU per frame of sequence s, sampled parameters (trials); d_s: with the defaults. The
trials stage runs its six studies one after another, each with up to N trials in flight (one
per worker); a joint trial runs all six sequences in one job; the evaluate and adaptive stages
run baseline, fixed and adaptive over all 11 sequences in one process. Left out: simulation or
ingest, descriptors, RTE scoring, the surrogate (each a single pass over the frames or less).
Environment: ADAPTUNE_BENCH_KITTI_FRAMES (default 20), ADAPTUNE_BENCH_KITTI_SAMPLES (3).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from common import Row, data_root, size

ADAPTERS = ("gicp", "kiss_icp", "ndt")
ENVIRONMENT_SEQUENCE = {"urban": "07", "residential": "00", "rural": "04", "highway": "01"}
TRAIN = ("00", "01", "02", "03", "04", "05")
ITERATIONS = 256
WORKERS = (1, 16, 64, 256)


@dataclass
class Cost:
    """Seconds per frame of one adapter in one environment: CPU and wall, defaults and sampled."""

    cpu_default: float
    wall_default: float
    cpu_sampled: float
    failed: int


def run() -> list[Row]:
    trajectories = data_root() / "kitti_trajectories"
    if not trajectories.is_dir():
        return []
    frames = int(os.environ.get("ADAPTUNE_BENCH_KITTI_FRAMES", size("20", "2")))
    samples = int(os.environ.get("ADAPTUNE_BENCH_KITTI_SAMPLES", size("3", "1")))
    counts = frame_counts(trajectories)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        paths, points = simulate(trajectories, frames, Path(tmp))
        for name in ADAPTERS:
            by_path = {path: adapter_cost(name, path, samples) for path in set(paths.values())}
            costs = {env: by_path[path] for env, path in paths.items()}
            rows += cost_rows(name, costs, points, samples)
            rows.append(protocol_row(name, costs, counts))
    return rows


def frame_counts(trajectories: Path) -> dict[str, dict[str, int]]:
    """Sequence -> environment -> frames of KITTI 00-10 (their simulated-KITTI schedules)."""
    from pipeline.sim.kitti import kitti_lidar_poses
    from pipeline.sim.kitti_world import SCHEDULES, frame_environments

    out = {}
    for seq in SCHEDULES:
        envs = frame_environments(seq, len(kitti_lidar_poses(trajectories / f"{seq}.txt")[0]))
        out[seq] = {env: envs.count(env) for env in ENVIRONMENT_SEQUENCE if env in envs}
    return out


def simulate(trajectories: Path, frames: int, tmp: Path) -> tuple[dict[str, Path], dict[str, int]]:
    """The first ``frames`` frames of each environment's sequence as MCAPs; mean points a scan."""
    from pipeline.sequence import SequenceReader
    from pipeline.sim.kitti_dataset import SimulateKittiSection, simulate_kitti_sequence

    paths, points = {}, {}
    for env, seq in size(ENVIRONMENT_SEQUENCE, {"rural": "04"}).items():
        section = SimulateKittiSection(trajectories=str(trajectories), train=[seq],
                                       windows=[(seq, 0, frames - 1)])
        paths[env] = simulate_kitti_sequence(section, seq, 0, tmp / f"{seq}.mcap").path
        with SequenceReader(paths[env]) as reader:
            points[env] = int(np.mean([len(scan.points_lidar) for scan in reader]))
    for env in ENVIRONMENT_SEQUENCE:  # a smoke run simulates one: it stands for them all
        paths.setdefault(env, paths["rural"])
        points.setdefault(env, points["rural"])
    return paths, points


def adapter_cost(name: str, path: Path, samples: int) -> Cost:
    """Per-frame cost of adapter ``name`` over the sequence ``path`` (module docstring)."""
    from pipeline.errors import AdaptuneError
    from pipeline.odometry import get_adapter, run_sequence
    from pipeline.sequence import SequenceReader

    adapter = get_adapter(name)
    with SequenceReader(path) as reader:
        n = len(reader)

    def timed(params: dict[str, float]) -> tuple[float, float]:
        cpu, wall = time.process_time(), time.perf_counter()
        run_sequence(adapter, path, params)
        return (time.process_time() - cpu) / n, (time.perf_counter() - wall) / n

    timed(adapter.space.defaults())  # warm-up: JIT caches, imports, page cache
    cpu_default, wall_default = timed(adapter.space.defaults())
    rng = np.random.default_rng(0)
    sampled, failed = [], 0
    for _ in range(samples):
        params = adapter.space.from_unit(rng.random(len(adapter.space.names)))
        try:
            sampled.append(timed(params)[0])
        except AdaptuneError:  # a diverging trial: scored with the penalty, its time not counted
            failed += 1
    return Cost(cpu_default, wall_default, float(np.mean(sampled)) if sampled else math.nan,
                failed)


def cost_rows(name: str, costs: dict[str, Cost], points: dict[str, int],
              samples: int) -> list[Row]:
    rows = []
    for env, c in costs.items():
        seq = ENVIRONMENT_SEQUENCE[env]
        failed = f", {c.failed} of {samples} sampled sets failed" if c.failed else ""
        rows.append(Row(f"{name} per frame, sim. HDL-64E {env} ({seq}, {points[env] // 1000}k "
                        "pts), defaults, CPU", 1000 * c.cpu_default, "ms",
                        f"wall {1000 * c.wall_default:.0f} ms; {samples} sampled parameter "
                        f"sets: CPU {1000 * c.cpu_sampled:.0f} ms{failed}"))
    return rows


def per_sequence(costs: dict[str, Cost], counts: dict[str, int], sampled: bool) -> float:
    """Core-seconds of one run of a sequence with environment frame ``counts``."""
    return sum(n * (costs[env].cpu_sampled if sampled else costs[env].cpu_default)
               for env, n in counts.items())


def protocol_row(name: str, costs: dict[str, Cost], counts: dict[str, dict[str, int]]) -> Row:
    """The full protocol's core-hours and its wall time on N workers (module docstring)."""
    train_run = sum(per_sequence(costs, counts[s], sampled=True) for s in TRAIN)
    evaluate = 3 * sum(per_sequence(costs, c, sampled=False) for c in counts.values())
    core_h = (2 * ITERATIONS * train_run + evaluate) / 3600
    walls = [(2 * math.ceil(ITERATIONS / n) * train_run + evaluate) / 3600 for n in WORKERS]
    frames = sum(sum(c.values()) for c in counts.values())
    return Row(f"{name}: full KITTI protocol ({frames} frames, {ITERATIONS} + {ITERATIONS} "
               "SMBO iterations), core-hours", core_h, "core-h",
               "wall on N workers: " + ", ".join(f"N={n}: {w:.1f} h"
                                                 for n, w in zip(WORKERS, walls, strict=True)))
