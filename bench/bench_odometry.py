"""Frames/s of every in-process odometry adapter (one core, baseline parameters).

- HDL-32E: 40 frames ray-cast with open3d (tests/odometry/odometry_data.py: 32 beams x 1800
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
sys.path.insert(0, str(HERE.parent / "tests" / "odometry"))

from common import Row, best_of, data_root  # noqa: E402

ADAPTERS = ("ndt", "gicp", "kiss_icp")


def _fps(adapter, scans, repeat: int = 2) -> float:
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
    from odometry_data import write_kitti_sequence, write_synthetic_sequence

    from pipeline.odometry import get_adapter
    from pipeline.sequence import SequenceReader

    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        seqs = {"HDL-32E sim": write_synthetic_sequence(Path(tmp) / "yard.mcap", n_frames=40)}
        kitti = data_root() / "kitti_mini" / "dataset"
        if kitti.is_dir():
            seqs["KITTI 04"] = write_kitti_sequence(Path(tmp) / "kitti04.mcap", kitti, "04", 10)
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
    return rows


def _street_overhead(tmp: Path, n_frames: int = 300) -> Row:
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
