"""The contract every registered ingest source passes: real inputs (built from KITTI scans
with each format's own writer) become a valid sequence MCAP with the same frames, stamps,
points and ground-truth poses."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers.source_inputs import (
    BAG_T0_NS,
    KittiFrames,
    load_kitti,
    typestore,
    write_bag,
    write_kitti_poses,
    write_pcd,
    write_tum,
)

from pipeline.errors import ConfigError
from pipeline.info import summarize_sequence
from pipeline.sequence import SequenceReader
from pipeline.sources import SOURCES, Source, get_source, source_names, write_sequence
from pipeline.sources.folder import FolderSource
from pipeline.sources.kitti import KittiSource
from pipeline.sources.mcap_file import McapSource
from pipeline.sources.poses import GroundTruthOptions
from pipeline.sources.rosbag import RosbagSource

N_FRAMES = 3
SEQ = "04"


@dataclass
class Case:
    source: Any
    stamps_ns: np.ndarray
    points: list[np.ndarray]
    T_world_lidar: np.ndarray | None


def _kitti(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    return Case(KittiSource(root, SEQ, end=N_FRAMES - 1), kf.stamps_ns, kf.points, kf.T_world_lidar)


def _bag_case(tmp: Path, kf: KittiFrames, **kw: Any) -> Case:
    path = write_bag(tmp / ("b.bag" if kw["ros"] == 1 else "b"), kf, **kw)
    gt = {"pose": GroundTruthOptions(gt_topic="/ground_truth"),
          "odom": GroundTruthOptions(),  # the only Odometry topic: found without gt_topic
          "tf": GroundTruthOptions(gt_topic="/tf", gt_child_frame="velodyne")}[kw["gt"]]
    src = RosbagSource(path, gt=gt)
    return Case(src, BAG_T0_NS + kf.stamps_ns, kf.points, kf.T_world_lidar)


def _ros1_bag_tum(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    """A ROS 1 bag without ground truth plus a TUM file of poses matched by time."""
    path = write_bag(tmp / "b.bag", kf, ros=1, gt=None)
    write_tum(tmp / "gt.tum", BAG_T0_NS + kf.stamps_ns, kf.T_world_lidar)
    src = RosbagSource(path, gt=GroundTruthOptions(poses=str(tmp / "gt.tum"), poses_format="tum"))
    return Case(src, BAG_T0_NS + kf.stamps_ns, kf.points, kf.T_world_lidar)


def _folder_pcd(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    """.pcd scans + the KITTI camera pose file + calib.txt (Tr) + times.txt."""
    d = tmp / "scans"
    d.mkdir()
    for k, pts in enumerate(kf.points):
        write_pcd(d / f"{k:06d}.pcd", pts)
    write_kitti_poses(tmp / "poses.txt", kf.T_world_cam)
    (tmp / "times.txt").write_text("\n".join(f"{t / 1e9:.6e}" for t in kf.stamps_ns) + "\n")
    gt = GroundTruthOptions(poses=str(tmp / "poses.txt"), poses_format="kitti",
                            extrinsic=str(root / "sequences" / SEQ / "calib.txt"))
    src = FolderSource(d, gt, times=tmp / "times.txt")
    return Case(src, kf.stamps_ns, kf.points, kf.T_world_lidar)


def _folder_bin_tum(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    """KITTI .bin scans (symlinked) + a TUM file that also gives the stamps."""
    d = tmp / "bins"
    d.mkdir()
    for b in kf.bins:
        os.symlink(b, d / b.name)
    write_tum(tmp / "gt.txt", BAG_T0_NS + kf.stamps_ns, kf.T_world_lidar)
    return Case(
        FolderSource(d, GroundTruthOptions(poses=str(tmp / "gt.txt"))), BAG_T0_NS + kf.stamps_ns,
        kf.points, kf.T_world_lidar
    )


def _mcap_ros2_recording(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    """The .mcap file of a ROS 2 bag (mcap storage), TF ground truth with a decoy frame."""
    bag = write_bag(tmp / "rec", kf, ros=2, storage="mcap", gt="tf")
    (mcap_file,) = bag.glob("*.mcap")
    src = McapSource(mcap_file, gt=GroundTruthOptions(gt_topic="/tf", gt_child_frame="velodyne"))
    return Case(src, BAG_T0_NS + kf.stamps_ns, kf.points, kf.T_world_lidar)


def _mcap_ros1_encoding(tmp: Path, root: Path, kf: KittiFrames) -> Case:
    """An MCAP in ROS 1 encoding (ros1msg schemas), PoseStamped ground truth."""
    from helpers.source_inputs import cloud_msg, gt_msg
    from mcap.writer import Writer

    ts = typestore(ros1=True)
    path = tmp / "ros1.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros1")
        chans = {}
        for topic, msgtype in (
            ("/points", "sensor_msgs/msg/PointCloud2"),
            ("/gt", "geometry_msgs/msg/PoseStamped"),
        ):
            text = ts.generate_msgdef(msgtype, ros_version=1)[0]
            sid = w.register_schema(msgtype.replace("/msg/", "/"), "ros1msg", text.encode())
            chans[topic] = w.register_channel(topic, "ros1", sid)
        for k, pts in enumerate(kf.points):
            t = int(BAG_T0_NS + kf.stamps_ns[k])
            data = ts.serialize_ros1(cloud_msg(ts, t, pts, True), "sensor_msgs/msg/PointCloud2")
            w.add_message(chans["/points"], log_time=t, publish_time=t, data=bytes(data))
            msgtype, msg = gt_msg(ts, "pose", t, kf.T_world_lidar[k], True)
            w.add_message(
                chans["/gt"],
                log_time=t,
                publish_time=t,
                data=bytes(ts.serialize_ros1(msg, msgtype)),
            )
        w.finish()
    return Case(
        McapSource(path, gt=GroundTruthOptions(gt_topic="/gt")), BAG_T0_NS + kf.stamps_ns,
        kf.points, kf.T_world_lidar
    )


CASES: dict[str, Callable[[Path, Path, KittiFrames], Case]] = {
    "kitti": _kitti,
    "rosbag/ros1-posestamped": lambda t, r, kf: _bag_case(t, kf, ros=1, gt="pose"),
    "rosbag/ros2-sqlite3-odometry-float64": lambda t, r, kf: _bag_case(
        t, kf, ros=2, storage="sqlite3", gt="odom", layout="xyzi64_ring"
    ),
    "rosbag/ros2-mcap-tf": lambda t, r, kf: _bag_case(t, kf, ros=2, storage="mcap", gt="tf"),
    "rosbag/ros1-tum-file": _ros1_bag_tum,
    "folder/pcd-kitti-poses": _folder_pcd,
    "folder/bin-tum": _folder_bin_tum,
    "mcap/ros2-recording": _mcap_ros2_recording,
    "mcap/ros1-encoding": _mcap_ros1_encoding,
}


@pytest.fixture(scope="module")
def kitti_frames(kitti_root: Path) -> KittiFrames:
    return load_kitti(kitti_root, SEQ, N_FRAMES)


@pytest.fixture(scope="module", params=sorted(CASES))
def ingested(
    request: pytest.FixtureRequest,
    kitti_root: Path,
    kitti_frames: KittiFrames,
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Case, Path, Any]:
    tmp = tmp_path_factory.mktemp(request.param.replace("/", "_"))
    case = CASES[request.param](tmp, kitti_root, kitti_frames)
    out = tmp / "out" / "seq.mcap"
    report = write_sequence(case.source, out)
    return case, out, report


def test_every_registered_source_has_a_contract_case() -> None:
    assert {name.split("/")[0] for name in CASES} == set(SOURCES) == set(source_names())


def test_registry_lookup() -> None:
    for name, cls in SOURCES.items():
        assert get_source(name) is cls and cls.name == name
    with pytest.raises(ConfigError, match=r"unknown source .velodyne_pcap.*kitti"):
        get_source("velodyne_pcap")


class TestSourceContract:
    """Run for every case of every registered source."""

    def test_is_a_registered_source(self, ingested: tuple[Case, Path, Any]) -> None:
        case, _, _ = ingested
        assert isinstance(case.source, Source)
        assert SOURCES[case.source.name] is type(case.source)
        assert case.source.expected_frames() in (None, len(case.points))

    def test_frames_stamps_and_points(self, ingested: tuple[Case, Path, Any]) -> None:
        case, out, report = ingested
        assert report.frames == len(case.points) and report.dropped_points == 0
        assert report.points == sum(len(p) for p in case.points)
        with SequenceReader(out) as r:
            assert len(r) == len(case.points) and r.info.frame_count == len(case.points)
            np.testing.assert_array_equal(r.stamps_ns, case.stamps_ns)
            for scan, expected in zip(r, case.points, strict=True):
                np.testing.assert_array_equal(scan.points_lidar, expected)
            assert r.info.source.startswith(case.source.name + ":")

    def test_ground_truth(self, ingested: tuple[Case, Path, Any]) -> None:
        case, out, report = ingested
        with SequenceReader(out) as r:
            gt = r.ground_truth()
        assert report.has_ground_truth and gt is not None
        np.testing.assert_allclose(gt, case.T_world_lidar, atol=1e-8)  # quaternion round trip

    def test_ground_truth_without_the_scans(self, ingested: tuple[Case, Path, Any]) -> None:
        """``ground_truth_poses`` (what the length check before ingesting reads) is the ground
        truth ``frames`` gives the scans, to the bit."""
        case, _, _ = ingested
        poses = case.source.ground_truth_poses()
        assert poses is not None
        frames = np.stack([f.T_world_lidar for f in case.source.frames()])
        np.testing.assert_array_equal(poses, frames)

    def test_stamps_without_the_scans(self, ingested: tuple[Case, Path, Any]) -> None:
        """``frame_stamps_ns`` (where a run is cut into pieces, before ingesting) is the stamps
        ``frames`` gives the scans."""
        case, _, _ = ingested
        stamps = case.source.frame_stamps_ns()
        assert stamps.dtype == np.int64
        np.testing.assert_array_equal(stamps, [f.stamp_ns for f in case.source.frames()])
        np.testing.assert_array_equal(stamps, case.stamps_ns)

    def test_info_summary(self, ingested: tuple[Case, Path, Any]) -> None:
        case, out, _ = ingested
        s = summarize_sequence(out)
        sizes = [len(p) for p in case.points]
        assert s.frames == len(sizes) and s.has_ground_truth
        assert s.points_per_scan == {
            "min": min(sizes),
            "median": float(np.median(sizes)),
            "max": max(sizes),
        }
        assert s.duration_s == pytest.approx((case.stamps_ns[-1] - case.stamps_ns[0]) / 1e9)
        steps = np.linalg.norm(np.diff(case.T_world_lidar[:, :3, 3], axis=0), axis=1)
        assert s.path_length_m == pytest.approx(steps.sum(), abs=1e-6) and s.path_length_m > 0.5
