"""`adaptune export` checked with evo itself: an anchored export of a good run needs no alignment
(`evo_ape` without -a is small), in the lidar frame against the exported ground truth and in
KITTI's camera frame against KITTI's own poses/NN.txt."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.posefile import read_kitti_poses, write_kitti_poses
from stages.cli import main

BIN = Path(sys.executable).parent
START, END = 3, 9  # a slice of KITTI 04 that does not start at its first frame (not at I)


def adaptune(*args: str) -> None:
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == 0, result.output


def evo_ape_rmse(fmt: str, ref: Path, est: Path) -> float:
    """APE RMSE [m] of evo_ape (translation, no alignment)."""
    done = subprocess.run([str(BIN / "evo_ape"), fmt, str(ref), str(est), "--no_warnings"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    return float(re.search(r"^\s*rmse\s+([0-9.eE+-]+)", done.stdout, re.M).group(1))  # type: ignore[union-attr]


@pytest.fixture(scope="module")
def run(kitti_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """KITTI 04 frames 3-9 ingested, and an NDT run over them (folder of both)."""
    if not (BIN / "evo_ape").exists():
        pytest.fail("evo is not installed (pip install -e '.[dev]')")
    root = tmp_path_factory.mktemp("export")
    adaptune("ingest", "kitti", str(kitti_root), "04", "--start", str(START), "--end", str(END),
             "--out", str(root / "04.mcap"))
    adaptune("run", "-a", "ndt", str(root / "04.mcap"), "--out", str(root / "traj.parquet"))
    return root


def test_anchored_export_needs_no_alignment(run: Path) -> None:
    adaptune("export", str(run / "04.mcap"), "--ground-truth", "--format", "tum",
             "--out", str(run / "gt.tum"))
    adaptune("export", str(run / "traj.parquet"), "--format", "tum", "--out", str(run / "a.tum"))
    adaptune("export", str(run / "traj.parquet"), "--format", "tum", "--out", str(run / "i.tum"),
             "--anchor", "identity")
    anchored = evo_ape_rmse("tum", run / "gt.tum", run / "a.tum")
    raw = evo_ape_rmse("tum", run / "gt.tum", run / "i.tum")
    assert anchored < 0.2, anchored
    assert raw > 5 * anchored and raw > 1.0, raw  # the ground truth starts 3 frames in


def test_kitti_camera_frame_matches_kittis_poses(run: Path, kitti_root: Path) -> None:
    reference = run / "04_slice.txt"
    poses = read_kitti_poses(kitti_root / "poses" / "04.txt")[START:END + 1]
    write_kitti_poses(reference, poses)
    # the ground truth goes back to KITTI's camera frame (up to the ingest's re-orthonormalised
    # rotations: KITTI's are orthonormal to ~1e-6)
    adaptune("export", str(run / "04.mcap"), "--ground-truth", "--format", "kitti",
             "--frame", "kitti-camera", "--out", str(run / "gt_cam.txt"))
    np.testing.assert_allclose(read_kitti_poses(run / "gt_cam.txt"), poses, atol=1e-6)
    # the estimate, anchored and in the camera frame, is close without alignment
    adaptune("export", str(run / "traj.parquet"), "--format", "kitti", "--frame",
             "kitti-camera", "--out", str(run / "est_cam.txt"))
    assert evo_ape_rmse("kitti", reference, run / "est_cam.txt") < 0.2
    # the calibration given by hand gives the same file
    adaptune("export", str(run / "traj.parquet"), "--format", "kitti", "--frame",
             "kitti-camera", "--calib", str(kitti_root / "sequences" / "04" / "calib.txt"),
             "--out", str(run / "est_cam2.txt"))
    assert (run / "est_cam2.txt").read_text() == (run / "est_cam.txt").read_text()
