"""Bad input: one line on stderr naming the file and the problem, exit 1, no output file."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.source_inputs import KittiFrames, load_kitti, typestore, write_bag, write_kitti_poses

from pipeline.sequence import SequenceReader
from stages.cli import main


def run_fails(args: list[str], out: Path, *fragments: str) -> str:
    """Run the CLI, check the failure contract, return the error line."""
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error: "), result.stderr
    assert "Traceback" not in result.output
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}.*")), "temporary file left behind"
    return lines[0]


@pytest.fixture
def mini_root(kitti_root: Path, tmp_path: Path) -> Path:
    """A KITTI root with the first 2 frames of sequence 04, copied so tests can damage it."""
    src, dst = kitti_root / "sequences" / "04", tmp_path / "kitti" / "sequences" / "04"
    (dst / "velodyne").mkdir(parents=True)
    for name in ("000000.bin", "000001.bin"):
        shutil.copy(src / "velodyne" / name, dst / "velodyne" / name)
    shutil.copy(src / "calib.txt", dst / "calib.txt")
    (dst / "times.txt").write_text("".join((src / "times.txt").read_text().splitlines(True)[:2]))
    (tmp_path / "kitti" / "poses").mkdir()
    lines = (kitti_root / "poses" / "04.txt").read_text().splitlines(True)[:2]
    (tmp_path / "kitti" / "poses" / "04.txt").write_text("".join(lines))
    return tmp_path / "kitti"


@pytest.fixture(scope="module")
def small_frames(kitti_root: Path) -> KittiFrames:
    """Two KITTI frames cut to 2000 points: enough for layout errors, fast to write."""
    kf = load_kitti(kitti_root, "04", 2)
    return replace(kf, points=[p[:2000] for p in kf.points])


def kitti_args(root: Path, out: Path) -> list[str]:
    return ["ingest", "kitti", str(root), "04", "--out", str(out)]


# ------------------------------------------------------------------ KITTI


def test_bin_size_not_a_multiple_of_16(mini_root: Path, tmp_path: Path) -> None:
    bad = mini_root / "sequences" / "04" / "velodyne" / "000001.bin"
    bad.write_bytes(bad.read_bytes()[:-5])
    out = tmp_path / "o" / "s.mcap"
    run_fails(kitti_args(mini_root, out), out, str(bad), "not a multiple of 16")


def test_non_finite_points_are_dropped_and_counted(mini_root: Path, tmp_path: Path) -> None:
    path = mini_root / "sequences" / "04" / "velodyne" / "000000.bin"
    pts = np.fromfile(path, np.float32).reshape(-1, 4)
    pts[[3, 70, 900], [0, 1, 2]] = [np.nan, np.inf, -np.inf]
    pts[5, 3] = np.nan  # a NaN intensity is not a non-finite point
    pts.tofile(path)
    out = tmp_path / "s.mcap"
    result = CliRunner().invoke(main, kitti_args(mini_root, out))
    assert result.exit_code == 0, result.output
    assert "(3 non-finite dropped)" in result.stderr  # the summary line
    with SequenceReader(out) as r:
        got = r[0].points_lidar
    keep = np.ones(len(pts), bool)
    keep[[3, 70, 900]] = False
    np.testing.assert_array_equal(got, pts[keep])


def test_all_nan_scan_is_an_error(mini_root: Path, tmp_path: Path) -> None:
    path = mini_root / "sequences" / "04" / "velodyne" / "000001.bin"
    np.full((50, 4), np.nan, np.float32).tofile(path)
    out = tmp_path / "s.mcap"
    run_fails(kitti_args(mini_root, out), out, str(path), "no finite points of 50")


def test_pose_file_line_count_does_not_match_scans(mini_root: Path, tmp_path: Path) -> None:
    poses = mini_root / "poses" / "04.txt"
    poses.write_text(poses.read_text() + poses.read_text().splitlines(True)[-1])
    out = tmp_path / "s.mcap"
    run_fails(kitti_args(mini_root, out), out, str(poses), "3 poses for 2 scans")


def test_folder_pose_file_line_count(
    kitti_root: Path, small_frames: KittiFrames, tmp_path: Path
) -> None:
    d = tmp_path / "scans"
    d.mkdir()
    for k, p in enumerate(small_frames.points):
        p.tofile(d / f"{k:03d}.bin")
    write_kitti_poses(tmp_path / "poses.txt", small_frames.T_world_cam[:1])
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "folder", d, "--poses", tmp_path / "poses.txt", "--out", out],
        out,
        str(tmp_path / "poses.txt"),
        "1 poses for 2 scans",
    )


def test_calib_without_tr(mini_root: Path, tmp_path: Path) -> None:
    calib = mini_root / "sequences" / "04" / "calib.txt"
    calib.write_text(
        "".join(ln for ln in calib.read_text().splitlines(True) if not ln.startswith("Tr"))
    )
    out = tmp_path / "s.mcap"
    run_fails(kitti_args(mini_root, out), out, str(calib), "no 'Tr'")


# ------------------------------------------------------------------ bags


def test_bag_without_pointcloud2(small_frames: KittiFrames, tmp_path: Path) -> None:
    from helpers.source_inputs import gt_msg
    from rosbags.rosbag2 import Writer

    ts = typestore(ros1=False)
    bag = tmp_path / "nopoints"
    with Writer(bag, version=9) as w:
        conn = w.add_connection("/ground_truth", "geometry_msgs/msg/PoseStamped", typestore=ts)
        msgtype, msg = gt_msg(ts, "pose", 10**18, np.eye(4), False)
        w.write(conn, 10**18, ts.serialize_cdr(msg, msgtype))
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "rosbag", bag, "--out", out],
        out,
        str(bag),
        "no sensor_msgs/PointCloud2 topic",
        "/ground_truth [geometry_msgs/msg/PoseStamped]",
    )


def test_bag_with_two_pointcloud2_topics_needs_topic(
    small_frames: KittiFrames, tmp_path: Path
) -> None:
    bag = write_bag(tmp_path / "two.bag", small_frames, ros=1, gt=None, extra_topics=("/other",))
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "rosbag", bag, "--out", out], out, "2 sensor_msgs/PointCloud2 topics", "--topic"
    )
    ok = CliRunner().invoke(
        main, ["ingest", "rosbag", str(bag), "--out", str(out), "--topic", "/velodyne_points"]
    )
    assert ok.exit_code == 0, ok.output
    with SequenceReader(out) as r:
        assert len(r) == 2 and r.ground_truth() is None


def test_unknown_pointfield_layout_int16_x(small_frames: KittiFrames, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "int16", small_frames, ros=2, gt=None, layout="x_int16")
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "rosbag", bag, "--out", out],
        out,
        str(bag),
        "/velodyne_points",
        "field 'x' has datatype 3",
    )


def test_unknown_pointfield_layout_missing_z(small_frames: KittiFrames, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "noz", small_frames, ros=2, storage="mcap", gt=None, layout="no_z")
    (mcap_file,) = bag.glob("*.mcap")
    out = tmp_path / "s.mcap"
    run_fails(["ingest", "mcap", mcap_file, "--out", out], out, str(mcap_file), "no field z")


def test_tf_ground_truth_needs_the_child_frame(small_frames: KittiFrames, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "tf.bag", small_frames, ros=1, gt="tf")
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "rosbag", bag, "--out", out, "--gt-topic", "/tf"],
        out,
        "/tf",
        "--gt-child-frame",
        "base_link, velodyne",
    )


def test_scans_outside_the_tum_time_span(small_frames: KittiFrames, tmp_path: Path) -> None:
    from helpers.source_inputs import BAG_T0_NS, write_tum

    bag = write_bag(tmp_path / "b.bag", small_frames, ros=1, gt=None)
    tum = tmp_path / "late.tum"
    write_tum(
        tum, BAG_T0_NS + small_frames.stamps_ns[1:] + 5 * 10**8, small_frames.T_world_lidar[1:]
    )
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "rosbag", bag, "--out", out, "--poses", tum],
        out,
        str(tum),
        "the scan at 1700000000.000 s lies outside the ground-truth time span",
    )


def test_truncated_ros1_bag(small_frames: KittiFrames, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "t.bag", small_frames, ros=1, gt=None)
    bag.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    out = tmp_path / "s.mcap"
    run_fails(["ingest", "rosbag", bag, "--out", out], out, str(bag), "cannot read bag")


@pytest.mark.timeout(30, method="signal")
@pytest.mark.parametrize("which", ["ros1", "ros2-storage"])
def test_a_fifo_as_a_bag_is_refused_without_blocking(small_frames: KittiFrames, tmp_path: Path,
                                                     which: str) -> None:
    """rosbags would wait forever on a FIFO (a .bag, or a ROS 2 bag's storage file)."""
    import os

    if which == "ros1":
        fifo = bag = tmp_path / "f.bag"
    else:
        bag = write_bag(tmp_path / "b", small_frames, ros=2, gt=None)
        (fifo,) = bag.glob("*.db3")
        fifo.unlink()
    os.mkfifo(fifo)
    out = tmp_path / "s.mcap"
    run_fails(["ingest", "rosbag", bag, "--out", out], out, str(fifo), "not a regular file")


# ------------------------------------------------------------------ MCAP


@pytest.fixture
def good_sequence(kitti_root: Path, tmp_path: Path) -> Path:
    out = tmp_path / "good.mcap"
    result = CliRunner().invoke(
        main, ["ingest", "kitti", str(kitti_root), "10", "--out", str(out), "--end", "2"]
    )
    assert result.exit_code == 0, result.output
    return out


def test_truncated_mcap(good_sequence: Path, tmp_path: Path) -> None:
    bad = tmp_path / "truncated.mcap"
    bad.write_bytes(good_sequence.read_bytes()[: good_sequence.stat().st_size * 2 // 3])
    out = tmp_path / "s.mcap"
    run_fails(["ingest", "mcap", bad, "--out", out], out, str(bad), "corrupt or truncated MCAP")
    run_fails(["info", bad], out, str(bad), "corrupt or truncated MCAP")


def test_corrupt_mcap_chunk(good_sequence: Path, tmp_path: Path) -> None:
    """Damaged bytes inside a scan chunk: the CRC check catches it while streaming."""
    data = bytearray(good_sequence.read_bytes())
    mid = len(data) // 3
    data[mid : mid + 64] = bytes(64)
    bad = tmp_path / "corrupt.mcap"
    bad.write_bytes(bytes(data))
    out = tmp_path / "s.mcap"
    run_fails(
        ["ingest", "mcap", bad, "--out", out, "--gt-topic", "/ground_truth/pose"],
        out,
        str(bad),
        "corrupt or truncated MCAP",
    )


def test_mcap_round_trip_of_a_sequence_mcap(good_sequence: Path, tmp_path: Path) -> None:
    """A sequence MCAP is itself a valid input of `ingest mcap` (ground truth by --gt-topic)."""
    out = tmp_path / "again.mcap"
    result = CliRunner().invoke(
        main,
        [
            "ingest",
            "mcap",
            str(good_sequence),
            "--out",
            str(out),
            "--gt-topic",
            "/ground_truth/pose",
        ],
    )
    assert result.exit_code == 0, result.output
    with SequenceReader(good_sequence) as a, SequenceReader(out) as b:
        assert len(a) == len(b) == 3
        np.testing.assert_array_equal(a.stamps_ns, b.stamps_ns)
        np.testing.assert_array_equal(a[2].points_lidar, b[2].points_lidar)
        np.testing.assert_allclose(a.ground_truth(), b.ground_truth(), atol=1e-12)
