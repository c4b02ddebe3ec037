"""A real external odometry for the ``command`` adapter tests: scan-to-scan GICP.

Usage: s2s_gicp.py SEQUENCE.mcap SCHEDULE.csv OUT.txt {kitti|tum}
Reads the scans with adaptune's SequenceReader, registers every scan to the previous one with
small_gicp (parameters per frame from the schedule CSV: downsampling_resolution,
max_correspondence_distance), writes T_world_lidar as KITTI (12 numbers a line) or TUM.
Environment ``S2S_FAIL=1`` makes it exit with status 3, ``S2S_SLEEP=<s>`` sleeps first,
``S2S_DROP=1`` leaves the last frame out of the output.
"""

from __future__ import annotations

import csv
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

import numpy as np
import small_gicp

from pipeline.geometry import rot_to_quat
from pipeline.sequence import SequenceReader


def main(sequence: str, schedule_csv: str, out: str, fmt: str) -> int:
    if os.environ.get("S2S_SLEEP"):
        time.sleep(float(os.environ["S2S_SLEEP"]))
    if os.environ.get("S2S_FAIL"):
        print("s2s_gicp: failing on purpose", file=sys.stderr)
        return 3
    with open(schedule_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    poses, stamps = [np.eye(4)], []
    prev = None
    delta = np.eye(4)
    with SequenceReader(sequence) as reader:
        for scan, row in zip(reader, rows, strict=True):
            stamps.append(scan.stamp_ns)
            res = float(row["downsampling_resolution"])
            cloud, tree = small_gicp.preprocess_points(scan.xyz.astype(np.float64), res,
                                                       num_neighbors=10, num_threads=1)
            if prev is not None:
                result = small_gicp.align(prev[0], cloud, prev[1], init_T_target_source=delta,
                                          max_correspondence_distance=float(
                                              row["max_correspondence_distance"]),
                                          num_threads=1)
                delta = result.T_target_source
                poses.append(poses[-1] @ delta)
            prev = (cloud, tree)
    if os.environ.get("S2S_DROP"):
        poses, stamps = poses[:-1], stamps[:-1]
    with open(out, "w") as fh:
        for T, stamp in zip(poses, stamps, strict=True):
            if fmt == "kitti":
                fh.write(" ".join(f"{v:.9e}" for v in T[:3, :].reshape(-1)) + "\n")
            else:
                q = rot_to_quat(T[:3, :3])
                vals = [stamp * 1e-9, *T[:3, 3], *q]
                fh.write(" ".join(f"{v:.9f}" for v in vals) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(*sys.argv[1:5]))
