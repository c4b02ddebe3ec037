"""What checking every chunk's CRC would cost the commands that read only the ground truth.

`export --ground-truth` and `metric rte` read a sequence MCAP's ground-truth chunks (CRC
checked); the scans' chunks (nearly all the bytes) they never open. Checking those too means
decompressing them (an MCAP chunk's CRC is of its uncompressed bytes): reading the file through
``SequenceReader.iter_every_chunk``, as `info` does. Measured on a KITTI sequence of kitti_mini
(real HDL-64E scans, ~120k points each), in process, best of 5: each command's own time, the
verification's, and their ratio against issue 58's rule (verify everywhere when it costs at
most 10 %); and both scaled to KITTI 00's length.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import Row, best_of, data_root, size

from pipeline.export import export_ground_truth, export_trajectory
from pipeline.metrics.trajectory_error import compare_files
from pipeline.sequence import SequenceReader, read_ground_truth
from pipeline.sources import ingest_kitti
from pipeline.trajectory import Trajectory, write_trajectory

SEQUENCE = "04"


def run() -> list[Row]:
    root = data_root() / "kitti_mini" / "dataset"
    with tempfile.TemporaryDirectory() as tmp:
        seq = Path(tmp) / f"{SEQUENCE}.mcap"
        ingest_kitti(root, SEQUENCE, seq, end=size(None, 3))
        gt = read_ground_truth(seq, "to bench with")
        with SequenceReader(seq) as reader:
            stamps = reader.stamps_ns.copy()
        traj = Path(tmp) / "t.parquet"
        write_trajectory(traj, Trajectory(range(len(gt)), stamps, gt), {"sequence": str(seq)})
        out = Path(tmp) / "out.txt"

        def verify() -> None:
            with SequenceReader(seq) as r:
                for _ in r.iter_every_chunk():
                    pass

        t_verify = best_of(verify)
        timed = {
            "export --ground-truth": best_of(lambda: export_ground_truth(seq, "kitti", out)),
            "export (anchored trajectory)": best_of(
                lambda: export_trajectory(traj, "kitti", out, sequence=seq)),
            "metric rte": best_of(lambda: compare_files(seq, [traj], 0.5)),
        }
        t_cli = cli_seconds(["export", str(seq), "--ground-truth", "--format", "kitti",
                             "--out", str(out)])
        frames, mb = len(gt), seq.stat().st_size / 1e6
    rows = [Row(f"verify every chunk's CRC, {frames} KITTI frames ({mb:.0f} MB MCAP)",
                t_verify * 1e3, "ms", f"{t_verify * 1e3 / frames:.1f} ms a frame", "")]
    for name, t in timed.items():
        rows.append(Row(f"{name}: verifying every chunk, % of its time", 100 * t_verify / t,
                        "%", f"{name} alone {t * 1e3:.1f} ms", "<= 10 % to verify all"))
    rows.append(Row("export --ground-truth as a command (process, best of 3): verifying, % of it",
                    100 * t_verify / t_cli, "%", f"{t_cli * 1e3:.0f} ms, Python start-up "
                    "included", "<= 10 % to verify all"))
    t_gt = timed["export --ground-truth"]
    n_00 = kitti_00_frames()
    rows.append(Row(f"verifying KITTI 00's {n_00} frames at this rate",
                    t_verify / frames * n_00, "s", "export --ground-truth alone at "
                    f"its rate: {t_gt / frames * n_00:.2f} s", ""))
    return rows


def kitti_00_frames() -> int:
    """Frames of KITTI odometry sequence 00, the longest: the poses of its ground-truth file."""
    from pipeline.posefile import read_kitti_poses

    return len(read_kitti_poses(data_root() / "kitti_trajectories" / "00.txt"))


def cli_seconds(args: list[str]) -> float:
    """Best wall time [s] of ``adaptune ARGS`` in a process of its own (of 3; 1 in a smoke
    run)."""
    best = float("inf")
    for _ in range(size(3, 1)):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "stages.cli", *args], check=True,
                       capture_output=True, cwd=Path(__file__).resolve().parents[1])
        best = min(best, time.perf_counter() - t0)
    return best
