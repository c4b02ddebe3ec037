"""Evaluation figures: the KITTI devkit metric against kiss-icp's C++ port (same run, same
trajectory), and rte_frames in DuckDB for 256 trials x 300 frames."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from common import Row, best_of, data_root, size

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # helpers

from helpers.evaluation_data import drifting, gt_path, write_sequence, write_study

from pipeline.database.store import build_database
from pipeline.metrics.kitti import kitti_sequence_error
from pipeline.metrics.section import DevkitSection
from pipeline.posefile import read_kitti_poses


def run() -> list[Row]:
    return [*kitti_rows(), *rte_frames_rows()]


def kitti_rows() -> list[Row]:
    from kiss_icp.metrics import sequence_error

    gt = read_kitti_poses(data_root() / "kitti_trajectories" / "00.txt")
    est = drifting(gt, seed=0, trans_sigma=0.01, rot_sigma=5e-4, scale=1.003)
    ours = kitti_sequence_error(gt, est)
    ref = sequence_error(gt, est)
    t_ours = best_of(lambda: kitti_sequence_error(gt, est), repeat=20)
    t_ref = best_of(lambda: sequence_error(gt, est), repeat=20)
    rel = abs(ours[0] - ref[0]) / ref[0]
    return [
        Row(f"KITTI devkit RTE, seq 00 ({len(gt)} frames), numpy", t_ours * 1e3, "ms",
            f"kiss-icp C++ port {t_ref * 1e3:.2f} ms", "not slower"),
        Row("KITTI t_err: |ours - kiss-icp| / kiss-icp", rel, "",
            f"{ours[0]:.6f} % vs {ref[0]:.6f} %", "float32 rounding (port returns float)"),
    ]


def rte_frames_rows(trials: int = size(256, 4), frames: int = size(300, 60)) -> list[Row]:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        gt = gt_path(frames, step_m=0.5, stop=None, seed=1)
        stamps = write_sequence(root / "seq" / "seq_0.mcap", gt)
        # write_study leaves trial 1 failed (no trajectory): one more trial gives `trials` runs
        write_study(root / "trials", "gicp", {"seq_0": (stamps, gt)}, trials + 1, ["kf_m"])
        summary = build_database(root / "adaptune.duckdb", root / "seq",
                                 {"trials": root / "trials"}, 25.0,
                                 DevkitSection.model_validate({}))
        t = summary.timings_s
        total = sum(t.values())
        n_traj = summary.trajectories
    return [
        Row(f"rte_frames, {n_traj} trials x {frames} frames (read Parquet + score)",
            t["trajectories"] + t["rte_frames"], "s", f"{summary.rte_frames} rows", "< 5 s"),
        Row("whole results database build (same data)", total, "s",
            f"rte_kitti {t['rte_kitti']:.2f} s", ""),
    ]


if __name__ == "__main__":
    from common import format_table

    print(format_table(run()))
