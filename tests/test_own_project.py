"""From a folder of recordings to a model artifact (issue 34's target): in a fresh copy of the
repository, a new user runs `adaptune init` on two ROS 2 bags and a folder of PCD scans, points
the trials at their own odometry (the ``command`` adapter running an external process:
tests/odometry/scripts/s2s_gicp.py), then `dvc repro` in the new project, and gets the model
artifact and the evaluation; every stage builds the adapter with the configured options.

The recordings are made here from real KITTI scans (every 8th point, 10 frames a recording):
the ROS 2 bags with rosbags' own writer (sqlite3 and mcap storage; an Odometry and a
PoseStamped ground-truth topic, neither named to adaptune), the PCD files with open3d, beside
KITTI's camera poses, calib.txt and times.txt. The params are the generated ones with a tiny
budget, as a user edits them for a first run.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers.odometry_data import command_options
from helpers.source_inputs import KittiFrames, load_kitti, write_bag, write_kitti_poses

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
STRIDE = 8

pytestmark = pytest.mark.slow


def frames(kitti_root: Path, seq: str) -> KittiFrames:
    kf = load_kitti(kitti_root, seq)
    return replace(kf, points=[p[::STRIDE].copy() for p in kf.points])


def write_pcd_folder(folder: Path, kf: KittiFrames, calib: Path) -> Path:
    """PCD scans written by open3d (x, y, z, intensity), KITTI's camera-0 poses, its
    calib.txt and times.txt beside them."""
    import open3d as o3d

    folder.mkdir(parents=True)
    for k, pts in enumerate(kf.points):
        cloud = o3d.t.geometry.PointCloud()
        cloud.point.positions = o3d.core.Tensor(pts[:, :3])
        cloud.point.intensity = o3d.core.Tensor(pts[:, 3:4])
        assert o3d.t.io.write_point_cloud(str(folder / f"{k:06d}.pcd"), cloud)
    write_kitti_poses(folder / "poses.txt", kf.T_world_cam)
    shutil.copy(calib, folder / "calib.txt")
    (folder / "times.txt").write_text("".join(f"{t / 1e9:.6f}\n" for t in kf.stamps_ns))
    return folder


def fresh_copy(root: Path) -> Path:
    """The repository as a new user gets it, as tests/test_pipeline_dvc.py makes one: its
    dvc.yaml and params.yaml, its code (symlinked; `adaptune` is the installation's)."""
    root.mkdir()
    for code in ("pipeline", "schemas", "stages", "studies"):
        (root / code).symlink_to(REPO / code, target_is_directory=True)
    for name in ("dvc.yaml", "params.yaml", ".dvcignore", ".gitignore"):
        shutil.copy(REPO / name, root / name)
    return root


def run(cwd: Path, env: dict[str, str], *args: str) -> str:
    done = subprocess.run(list(args), cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, f"{' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


def tiny(params: dict) -> dict:
    """A first run's budget: 4 m sub-trajectories, 3 trials a recording, a small surrogate; the
    user's own odometry through the ``command`` adapter."""
    params["base"]["length_m"] = 4.0
    params["descriptors"].update(pca_dim=4, range_bins=3, workers=1)
    params["trials"].update(iterations=3, startup_trials=2, workers=1, algorithm="command",
                            adapter_options=command_options())
    params["fixed"].update(iterations=2, warm_start=1, workers=1)
    params["surrogate"].update(n_sobol=16, cv_max_frames=20)
    params["devkit"]["lengths_m"] = [2.0, 4.0]
    params["evaluate"]["workers"] = 1
    return params


def test_recordings_to_a_model_with_init_and_dvc_repro(kitti_root: Path, tmp_path: Path) -> None:
    from pipeline.outputs import read_summary
    from pipeline.runtime import load_model
    from pipeline.sequence import SequenceReader

    recordings = tmp_path / "recordings"
    recordings.mkdir()
    write_bag(recordings / "drive1", frames(kitti_root, "04"), ros=2, storage="sqlite3",
              gt="odom")
    write_bag(recordings / "drive2", frames(kitti_root, "06"), ros=2, storage="mcap", gt="pose")
    write_pcd_folder(recordings / "scans", frames(kitti_root, "01"),
                     kitti_root / "sequences" / "01" / "calib.txt")
    clone = fresh_copy(tmp_path / "adaptune")
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    project = tmp_path / "myproject"
    out = run(clone, env, str(BIN / "adaptune"), "init", str(project),
              "--recording", str(recordings / "drive1"), "--recording",
              str(recordings / "drive2"), "--recording", str(recordings / "scans"),
              "--length", "4")
    assert "3 recordings (2 train, 1 validation)" in out
    params = yaml.safe_load((project / "params.yaml").read_text())
    assert [(s["kind"], s["split"], s.get("gt_topic") or s.get("poses"))
            for s in params["data"]["sources"]] == [
        ("rosbag", "train", "/odom"), ("rosbag", "train", "/ground_truth"),
        ("folder", "validation", str(recordings / "scans" / "poses.txt"))]
    (project / "params.yaml").write_text(yaml.safe_dump(tiny(params), sort_keys=False))
    run(project, env, "git", "init", "-q", "-b", "main")
    run(project, env, str(BIN / "dvc"), "init", "-q")
    log = run(project, env, str(BIN / "dvc"), "repro")
    for stage in ("ingest", "descriptors", "trials", "fixed", "rte", "surrogate", "adaptive",
                  "evaluate"):
        assert f"Running stage '{stage}'" in log
    index = json.loads((project / "data/recordings/index.json").read_text())
    assert index == {"train": ["drive1", "drive2"], "validation": ["scans"]}
    for name, seq in (("drive1", "04"), ("drive2", "06"), ("scans", "01")):
        kf = load_kitti(kitti_root, seq)
        with SequenceReader(project / f"data/recordings/{name}.mcap") as reader:
            assert len(reader) == 10
            np.testing.assert_allclose(reader.ground_truth(), kf.T_world_lidar, atol=1e-5)
    model = load_model(project / "model", expected_algorithm="command")
    assert model.names == ["max_correspondence_distance", "downsampling_resolution"]
    assert len(model.surrogate.rows_t) > 0
    assert set(model.novelty_fallback["per_sequence"]) == {"drive1", "drive2"}
    metrics = read_summary(project / "metrics/evaluation.json")  # the figures and their record
    assert list(metrics["sequences"]) == ["scans"] and metrics["algorithm"] == "command"
    assert all(0 < v < 100 for v in metrics["rte_pct"].values()), metrics["rte_pct"]
    assert "Stage 'evaluate' didn't change" in run(project, env, str(BIN / "dvc"), "repro")
