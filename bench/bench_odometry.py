"""Frames/s of every in-process odometry adapter (one core, baseline parameters).

- HDL-32E: 40 frames ray-cast with open3d (tests/helpers/odometry_data.py: 32 beams x 1800
  azimuth steps, ~56k points a scan, a walled yard with boxes, 0.8 m a frame).
- KITTI: kitti_mini sequence 04 frames 0-9 (real HDL-64E, ~124k points a scan).
Scans are decoded beforehand: the figure is the bare odometry (``adapter.run``). The last rows
give ``run_sequence``'s overhead (MCAP reading, schedule and result checks) over the bare run:
on the 40-frame yard (where opening the file and decoding the first scans weigh most) and on a
300-frame simulated street (``pipeline.sim``, the length of a training sequence's trial).
The ``command`` adapter is not timed here (its speed is the external program's).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))  # helpers

from common import Row, best_of, data_root, size  # noqa: E402

ADAPTERS = ("ndt", "gicp", "kiss_icp")


def _fps(adapter, scans, repeat: int = size(2, 1)) -> float:
    from pipeline.odometry.base import Schedule

    sched = Schedule.constant(adapter.space.defaults(), len(scans))
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        adapter.run(scans, sched)
        best = min(best, time.perf_counter() - t0)
    return len(scans) / best


def _overhead_pct(adapter, path: Path, scans) -> float:
    from pipeline.odometry import run_sequence
    from pipeline.odometry.base import Schedule

    sched = Schedule.constant(adapter.space.defaults(), len(scans))
    bare = best_of(lambda: adapter.run(scans, sched), repeat=3)
    full = best_of(lambda: run_sequence(adapter, path, adapter.space.defaults()), repeat=3)
    return 100.0 * (full - bare) / bare


def run() -> list[Row]:
    from helpers.odometry_data import write_kitti_sequence, write_synthetic_sequence

    from pipeline.odometry import get_adapter
    from pipeline.sequence import SequenceReader

    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        seqs = {"HDL-32E sim": write_synthetic_sequence(Path(tmp) / "yard.mcap",
                                                          n_frames=size(40, 3))}
        kitti = data_root() / "kitti_mini" / "dataset"
        if kitti.is_dir():
            seqs["KITTI 04"] = write_kitti_sequence(Path(tmp) / "kitti04.mcap", kitti, "04",
                                                      size(10, 2))
        for label, path in seqs.items():
            with SequenceReader(path) as reader:
                scans = list(reader)
            points = sum(len(s.points_lidar) for s in scans) // len(scans)
            for name in ADAPTERS:
                adapter = get_adapter(name)
                target = ">= 50 frames/s" if (name == "ndt" and "32" in label) else ""
                rows.append(Row(f"{name} on {label} ({points // 1000}k pts), frames/s",
                                _fps(adapter, scans), "frames/s", "", target))
            if label == "HDL-32E sim":
                rows.append(Row(f"run_sequence overhead (ndt, {label}, {len(scans)} frames)",
                                _overhead_pct(get_adapter("ndt"), path, scans), "%", "",
                                "<= 5 % (incl. MCAP decode)"))
        rows.append(_street_overhead(Path(tmp)))
        rows.extend(_ndt_against_reference(Path(tmp)))
    return rows


def _ndt_against_reference(tmp: Path, n_frames: int = size(300, 5),
                           n_sets: int = size(8, 1)) -> list[Row]:
    """Frames/s of ``ndt`` over a simulated cave and street with ``n_sets`` random parameter
    sets (as a study's trials draw them; CPU time of one process), compiled
    (pipeline/odometry/ndt_kernel.py) against the numpy reference (bench/reference/ndt_reference.py)
    in the same run, and the largest difference of their positions."""
    from functools import partial

    import numpy as np
    from reference.ndt_reference import ReferenceNdtOdometry

    from pipeline.odometry import get_adapter
    from pipeline.odometry.base import Schedule, run_streaming
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import SimSpec, simulate_sequence

    rng = np.random.default_rng(16)
    sets = [{"resolution": float(r), "keyframe_interval": float(k)}
            for r, k in rng.uniform([1.0, 0.0], [10.0, 10.0], (n_sets, 2))]
    cpu = {"compiled": 0.0, "reference": 0.0}
    frames, worst_m = 0, 0.0
    for label in size(("cave", "street"), ("street",)):
        path = simulate_sequence(SimSpec(label, 3, n_frames), tmp / f"{label}.mcap").path
        with SequenceReader(path) as reader:
            scans = list(reader)
        adapter = get_adapter("ndt")
        adapter.warm(scans)  # and compiles the kernels, as does the next line the reference's
        reference = partial(ReferenceNdtOdometry, options=adapter.options,
                            sources=adapter.sources)
        run_streaming(reference, scans[:2], Schedule.constant(sets[0], 2))
        for params in sets:
            schedule = Schedule.constant(params, len(scans))
            t0 = time.process_time()
            new = adapter.run(scans, schedule)
            t1 = time.process_time()
            ref = run_streaming(reference, scans, schedule)
            cpu["compiled"] += t1 - t0
            cpu["reference"] += time.process_time() - t1
            frames += len(scans)
            worst_m = max(worst_m, float(np.abs(new.T_world_lidar[:, :3, 3]
                                                - ref.T_world_lidar[:, :3, 3]).max()))
    what = f"{n_sets} random parameter sets x simulated cave + street, {frames} frames"
    return [Row(f"ndt frames/s, compiled ({what})", frames / cpu["compiled"], "frames/s",
                f"{frames / cpu['reference']:.0f} numpy reference", ">= 2x the reference"),
            Row("ndt compiled vs numpy reference: largest position difference", worst_m, "m",
                "", "<= 1e-9 m")]


def _street_overhead(tmp: Path, n_frames: int = size(300, 5)) -> Row:
    """run_sequence overhead on a simulated street of ``n_frames`` HDL-32E frames."""
    from pipeline.odometry import get_adapter
    from pipeline.sequence import SequenceReader
    from pipeline.sim.simulate import SimSpec, simulate_sequence

    path = simulate_sequence(SimSpec("street", 1, n_frames), tmp / "street.mcap").path
    with SequenceReader(path) as reader:
        scans = list(reader)
    return Row(f"run_sequence overhead (ndt, simulated street, {n_frames} frames)",
               _overhead_pct(get_adapter("ndt"), path, scans), "%", "",
               "<= 5 % (incl. MCAP decode)")
