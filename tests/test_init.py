"""`adaptune init DIR` (issue 34): params.yaml and dvc.yaml of a new project from a list of
recordings, each recording's kind, topics and ground truth found where unambiguous.
(tests/test_own_project.py takes such a project through `dvc repro`.)"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner
from helpers.source_inputs import KittiFrames, load_kitti, write_bag, write_kitti_poses, write_pcd

from pipeline.config import load_params
from pipeline.project import DVC_YAML, LEFT_OUT
from stages.cli import main

N = 3


@pytest.fixture(scope="module")
def frames(kitti_root: Path) -> KittiFrames:
    kf = load_kitti(kitti_root, "04", N)
    return replace(kf, points=[p[::50].copy() for p in kf.points])


LENGTH_M = 2.0
"""base.length_m of the test projects: the recordings of N frames run about 2.6 m."""


def init(*args: object) -> tuple[int, str]:
    """`adaptune init ARGS` (with --length LENGTH_M unless ARGS give one)."""
    length = [] if "--length" in args else ["--length", str(LENGTH_M)]
    result = CliRunner().invoke(main, ["init", *map(str, args), *length])
    return result.exit_code, result.output


def scan_folder(folder: Path, kf: KittiFrames, calib: Path) -> Path:
    """PCD scans with KITTI's camera poses, its calib.txt and times.txt beside them."""
    folder.mkdir(parents=True)
    for k, pts in enumerate(kf.points):
        write_pcd(folder / f"{k:06d}.pcd", pts)
    write_kitti_poses(folder / "poses.txt", kf.T_world_cam)
    (folder / "calib.txt").write_text(calib.read_text())
    (folder / "times.txt").write_text("".join(f"{t / 1e9:.6f}\n" for t in kf.stamps_ns))
    return folder


def test_a_list_of_recordings_makes_a_project(frames: KittiFrames, kitti_root: Path,
                                              tmp_path: Path) -> None:
    """A list file: a ROS 1 bag with two point-cloud topics (its line names one), a ROS 2 bag
    (its only Odometry topic found), a scan folder (poses, calib and times found beside the
    scans) and a KITTI sequence folder; --validation picks the split of one, the list file
    another's. Paths inside the project are relative to it."""
    project = tmp_path / "project"
    rec = project / "recordings"
    rec.mkdir(parents=True)
    write_bag(rec / "a.bag", frames, ros=1, gt="pose", extra_topics=("/other_points",))
    write_bag(rec / "b", frames, ros=2, storage="sqlite3", gt="odom")
    scan_folder(rec / "scans", frames, kitti_root / "sequences" / "04" / "calib.txt")
    (project / "recordings.txt").write_text(
        "# path [key=value ...]\n"
        "recordings/a.bag topic=/velodyne_points sensor=hdl64\n"
        "recordings/b\n"
        "recordings/scans\n"
        f"{kitti_root}/sequences/06 split=test\n")
    code, out = init(project, "--list", project / "recordings.txt",
                     "--validation", rec / "scans")
    assert code == 0, out
    assert "4 recordings (2 train, 1 validation, 1 test), evaluated on validation and test" in out
    params = yaml.safe_load((project / "params.yaml").read_text())
    assert params["data"]["sources"] == [
        {"kind": "rosbag", "path": "recordings/a.bag", "topic": "/velodyne_points",
         "sensor": "hdl64", "split": "train", "gt_topic": "/ground_truth"},
        {"kind": "rosbag", "path": "recordings/b", "split": "train",
         "topic": "/velodyne_points", "gt_topic": "/odom"},
        {"kind": "folder", "path": "recordings/scans", "times": "recordings/scans/times.txt",
         "extrinsic": "recordings/scans/calib.txt", "poses": "recordings/scans/poses.txt",
         "split": "validation"},
        {"kind": "kitti", "path": str(kitti_root), "sequences": ["06"], "split": "test"}]
    assert params["base"]["sequences"] == "data/recordings"
    assert params["base"]["length_m"] == LENGTH_M
    assert params["evaluate"]["splits"] == ["validation", "test"]
    load_params(project / "params.yaml")  # every section valid
    ours = yaml.safe_load(DVC_YAML.read_text())
    new = yaml.safe_load((project / "dvc.yaml").read_text())
    assert list(new["stages"]) == [s for s in ours["stages"] if s not in LEFT_OUT]
    for name, stage in new["stages"].items():  # the same commands, outputs and params
        assert {k: v for k, v in stage.items() if k != "deps"} == {
            k: v for k, v in ours["stages"][name].items() if k != "deps"}
        assert not any(str(d).split("/")[0] in ("pipeline", "stages", "schemas")
                       for d in stage.get("deps", []))
    assert new["stages"]["ingest"]["deps"] == [
        "recordings/a.bag", "recordings/b", "recordings/scans",
        f"{kitti_root}/sequences/06", f"{kitti_root}/poses"]
    assert "plots/generalization.csv" not in str(new["plots"])
    assert len(new["plots"]) == len(ours["plots"]) - 2
    code, out = init(project, "--recording", rec / "b")
    assert code == 1 and "params.yaml: exists; give --force to overwrite it" in out


def test_the_last_recording_is_validation_and_what_is_missing_is_named(
        frames: KittiFrames, kitti_root: Path, tmp_path: Path) -> None:
    write_bag(tmp_path / "a", frames, ros=2, storage="mcap", gt="pose")
    write_bag(tmp_path / "b.bag", frames, ros=1, gt="odom")
    code, out = init(tmp_path / "p", "-r", tmp_path / "a", "-r", tmp_path / "b.bag")
    assert code == 0, out
    sources = yaml.safe_load((tmp_path / "p" / "params.yaml").read_text())["data"]["sources"]
    assert [(s["path"], s["split"]) for s in sources] == [
        (str(tmp_path / "a"), "train"), (str(tmp_path / "b.bag"), "validation")]
    # two point-cloud topics, no ground truth, no recording at all: one line each
    write_bag(tmp_path / "two.bag", frames, ros=1, gt="pose", extra_topics=("/more",))
    write_bag(tmp_path / "nogt.bag", frames, ros=1, gt=None)
    (tmp_path / "notes").mkdir()
    for bad, message in ((tmp_path / "two.bag", "2 sensor_msgs/PointCloud2 topics"),
                         (tmp_path / "nogt.bag", "no ground truth found (tuning needs it): "
                          "give its gt_topic"),
                         (tmp_path / "notes", "cannot tell what kind of recording this is"),
                         (tmp_path / "none.bag", "no such recording")):
        code, out = init(tmp_path / "q", "-r", tmp_path / "a", "-r", bad)
        assert code == 1 and out.count("\n") == 1 and message in out, out
    code, out = init(tmp_path / "q", "-r", tmp_path / "a", "--validation", tmp_path / "b.bag")
    assert code == 1 and "named for the validation split but not a recording" in out
    assert not (tmp_path / "q").exists()


def test_a_kitti_root_is_its_sequences(kitti_root: Path, tmp_path: Path) -> None:
    """A KITTI root stands for its sequences with ground truth: the last one is validation, the
    others one train source; the summary names every sequence (issue 57.5: it printed the
    root once a sequence, without their numbers); --validation takes a sequence folder."""
    code, out = init(tmp_path / "p", "-r", kitti_root, "--length", "1")  # 10 runs 1.7 m
    assert code == 0, out
    sources = yaml.safe_load((tmp_path / "p" / "params.yaml").read_text())["data"]["sources"]
    assert sources == [
        {"kind": "kitti", "path": str(kitti_root), "sequences": ["01", "04", "06"],
         "split": "train"},
        {"kind": "kitti", "path": str(kitti_root), "sequences": ["10"], "split": "validation"}]
    assert "4 recordings (3 train, 1 validation)" in out
    lines = [ln.split() for ln in out.splitlines() if ln.startswith("  ")]
    assert [(ln[0], ln[1], ln[2]) for ln in lines] == [
        (split, "kitti", f"{kitti_root}/sequences/{seq}")
        for split, seq in (("train", "01"), ("train", "04"), ("train", "06"),
                           ("validation", "10"))]
    assert all(ln[4] == f"{kitti_root}/poses/{seq}.txt)" for ln, seq in
               zip(lines, ("01", "04", "06", "10"), strict=True))
    code, out = init(tmp_path / "q", "-r", kitti_root, "--validation",
                     kitti_root / "sequences" / "04", "--length", "1")
    assert code == 0, out
    sources = yaml.safe_load((tmp_path / "q" / "params.yaml").read_text())["data"]["sources"]
    assert [(s["sequences"], s["split"]) for s in sources] == [
        (["01"], "train"), (["04"], "validation"), (["06", "10"], "train")]
    new = yaml.safe_load((tmp_path / "q" / "dvc.yaml").read_text())
    assert new["stages"]["ingest"]["deps"] == [
        f"{kitti_root}/sequences/01", f"{kitti_root}/poses",
        *(f"{kitti_root}/sequences/{seq}" for seq in ("04", "06", "10"))]


def test_a_recording_shorter_than_the_rte_length_is_refused_by_name(
        frames: KittiFrames, tmp_path: Path) -> None:
    """init (base.length_m: --length, or the code's 25 m) and the ingest stage (params
    base.length_m) refuse a recording whose ground truth runs no longer, naming it, before
    anything is written."""
    write_bag(tmp_path / "long", frames, ros=2, storage="mcap", gt="pose")
    write_bag(tmp_path / "short.bag", replace(frames, bins=frames.bins[:2],
                                              points=frames.points[:2],
                                              stamps_ns=frames.stamps_ns[:2],
                                              T_world_cam=frames.T_world_cam[:2]),
              ros=1, gt="odom")
    code, out = init(tmp_path / "p", "-r", tmp_path / "long", "-r", tmp_path / "short.bag",
                     "--length", "2")
    assert code == 1 and out.count("\n") == 1, out
    assert f"{tmp_path / 'short.bag'}: ground truth runs 1.3 m, not longer than length_m=2.0" \
        in out and "adaptune init --length" in out
    assert not (tmp_path / "p").exists()
    code, out = init(tmp_path / "p", "-r", tmp_path / "long", "--length", "1")
    assert code == 0, out
    params_path = tmp_path / "p" / "params.yaml"
    params = yaml.safe_load(params_path.read_text())
    params["base"]["length_m"] = 5.0  # the long one runs 2.6 m
    params_path.write_text(yaml.safe_dump(params))
    out_dir = tmp_path / "p" / "data" / "recordings"
    result = CliRunner().invoke(main, ["ingest-set", "--params", str(params_path),
                                       "--out", str(out_dir)])
    assert result.exit_code == 1, result.output
    assert (f"data.sources: {tmp_path / 'long'} (sequence long): ground truth runs 2.6 m, not "
            "longer than length_m=5.0") in result.stderr
    assert not out_dir.exists()


def test_a_pose_file_that_reads_as_none_is_named_with_the_reason(
        frames: KittiFrames, kitti_root: Path, tmp_path: Path) -> None:
    """A scan folder whose one pose file has no format that can be told: the error names the
    file and why (issue 57.5: it was dropped, and the user read "no ground truth found")."""
    folder = scan_folder(tmp_path / "scans", frames, kitti_root / "sequences" / "04" / "calib.txt")
    (folder / "poses.txt").unlink()
    (folder / "gt.csv").write_text("".join(
        f"{t / 1e9:.6f},{T[0, 3]},{T[1, 3]},{T[2, 3]},0,0,0,1\n"
        for t, T in zip(frames.stamps_ns, frames.T_world_lidar, strict=True)))
    code, out = init(tmp_path / "p", "-r", folder)
    assert code == 1 and out.count("\n") == 1, out
    assert (f"{folder}: no pose file beside the scans reads as one: gt.csv: 8 numbers a line, "
            "comma-separated without an EuRoC header could be tum or euroc; give "
            "--poses-format tum|euroc; give poses (and poses_format)") in out
    code, out = init(tmp_path / "p", "--list", _listed(tmp_path, folder, "poses_format=tum"))
    assert code == 0, out


def _listed(tmp: Path, folder: Path, *options: str) -> Path:
    path = tmp / "list.txt"
    path.write_text(f"{folder} poses={folder / 'gt.csv'} {' '.join(options)}\n")
    return path
