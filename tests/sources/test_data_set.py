"""The params section ``data`` (issue 34): recordings of every kind -> a sequences folder and its
index.json through `adaptune ingest-set`, relative paths read from the params file's folder."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers.source_inputs import (
    BAG_T0_NS,
    KittiFrames,
    load_kitti,
    write_bag,
    write_kitti_poses,
    write_pcd,
)

from pipeline.sequence import SequenceReader
from stages.cli import main

N = 4


@pytest.fixture(scope="module")
def frames(kitti_root: Path) -> KittiFrames:
    kf = load_kitti(kitti_root, "04", N)
    return replace(kf, points=[p[::20].copy() for p in kf.points])


def ingest_set(params: Path, out: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["ingest-set", "--params", str(params), "--out", out])
    return result.exit_code, result.output


def write_params(path: Path, sources: list[dict[str, Any]]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump({"base": {"length_m": 1.0}, "data": {"sources": sources}},
                                   sort_keys=False))
    return path


def test_every_kind_of_recording_becomes_one_data_set(
        frames: KittiFrames, kitti_root: Path, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A ROS 1 bag (its only Odometry topic the ground truth), a ROS 2 bag folder, a PCD
    folder with camera-frame KITTI poses and calib.txt, and a KITTI sequence: each a sequence
    MCAP with its exact ground truth, in its split, though the stage runs in another folder."""
    project = tmp_path / "project"
    (project / "rec").mkdir(parents=True)
    write_bag(project / "rec" / "drive1.bag", frames, ros=1, gt="odom")
    write_bag(project / "rec" / "drive2", frames, ros=2, storage="mcap", gt="pose")
    scans = project / "rec" / "scans"
    scans.mkdir()
    for k, pts in enumerate(frames.points):
        write_pcd(scans / f"{k:06d}.pcd", pts)
    write_kitti_poses(scans / "poses.txt", frames.T_world_cam)
    (scans / "calib.txt").write_text(
        (kitti_root / "sequences" / "04" / "calib.txt").read_text())
    params = write_params(project / "params.yaml", [
        {"kind": "rosbag", "path": "rec/drive1.bag", "split": "train", "sensor": "hdl64"},
        {"kind": "rosbag", "path": "rec/drive2", "split": "train", "gt_topic": "/ground_truth"},
        {"kind": "folder", "path": "rec/scans", "split": "validation",
         "poses": "rec/scans/poses.txt", "extrinsic": "rec/scans/calib.txt"},
        {"kind": "kitti", "path": str(kitti_root), "sequences": ["06"], "end": 2,
         "split": "test"}])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    code, out = ingest_set(params, "out")
    assert code == 0, out
    assert "out/index.json: 2 train, 1 validation, 1 test sequences" in out
    index = json.loads((elsewhere / "out" / "index.json").read_text())
    assert index == {"train": ["drive1", "drive2"], "validation": ["scans"], "test": ["06"]}
    for name in ("drive1", "drive2", "scans"):
        with SequenceReader(elsewhere / "out" / f"{name}.mcap") as r:
            assert len(r) == N
            np.testing.assert_allclose(r.ground_truth(), frames.T_world_lidar, atol=1e-6)
            np.testing.assert_array_equal(r[1].points_lidar, frames.points[1])
            stamps = frames.stamps_ns + (0 if name == "scans" else BAG_T0_NS)
            if name != "scans":  # the folder's stamps: 10 Hz (no times file)
                np.testing.assert_array_equal(r.stamps_ns, stamps)
            where = r.info.source.split(":")[1]
            assert Path(where).is_absolute() and Path(where).exists(), r.info.source
    with SequenceReader(elsewhere / "out" / "drive1.mcap") as r:
        assert r.info.sensor == "hdl64"
        assert r.info.extra["ground_truth"] == "topic /odom (found: the only pose topic)"
    with SequenceReader(elsewhere / "out" / "06.mcap") as r:
        assert len(r) == 3 and r.info.name == "06"


@pytest.mark.parametrize("sources, message", [
    ([{"kind": "kitti", "path": "k", "sequences": ["04"], "split": "validation"}],
     "data.sources: no recording in split 'train'"),
    ([{"kind": "folder", "path": "scans", "gt_topic": "/odom"}],
     "a scan folder has no topics: give its ground truth as poses"),
    ([{"kind": "kitti", "path": "k", "sequences": ["04", "06"], "name": "x"}],
     "a name needs exactly one sequence"),
    ([{"kind": "rosbag", "path": "a.bag", "gt_topic": "/odom", "poses": "p.txt"}],
     "give either gt_topic or poses, not both"),
    ([{"kind": "tape", "path": "a.bag"}], "data.sources.0: Input tag 'tape' found using 'kind'"),
    ([{"kind": "rosbag", "path": "a.bag", "split": "dev"}], "data.sources.0.rosbag.split"),
    ([{"kind": "rosbag", "path": "a.bag", "name": "../x"}], "data.sources.0.rosbag.name"),
])
def test_a_bad_source_is_one_line(tmp_path: Path, sources: list[dict[str, Any]],
                                  message: str) -> None:
    code, out = ingest_set(write_params(tmp_path / "params.yaml", sources),
                           str(tmp_path / "out"))
    assert code == 1 and out.count("\n") == 1 and message in out, out
    assert not (tmp_path / "out" / "index.json").exists()


def test_two_recordings_of_one_name_are_refused_before_any_is_written(
        frames: KittiFrames, kitti_root: Path, tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    write_bag(tmp_path / "a" / "04.bag", frames, ros=1, gt="pose")
    params = write_params(tmp_path / "params.yaml", [
        {"kind": "rosbag", "path": "a/04.bag"},
        {"kind": "kitti", "path": str(kitti_root), "sequences": ["04"], "split": "validation"}])
    code, out = ingest_set(params, str(tmp_path / "out"))
    assert code == 1 and "two recordings are named '04'" in out and "give one of them a name" in out
    assert not list((tmp_path / "out").glob("*.mcap"))
