"""The ``command`` adapter against a real external process (tests/odometry/scripts/s2s_gicp.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers.odometry_data import SCRIPTS, Seq, command_options, final_errors

from pipeline.errors import ConfigError, OdometryError, TrialTimeout
from pipeline.odometry import check_trajectory, get_adapter, run_sequence
from pipeline.odometry.base import Schedule
from pipeline.trajectory import Trajectory


def test_tum_output_matches_kitti_output(synthetic_seq: Seq) -> None:
    kitti = run_sequence(get_adapter("command", **command_options("kitti")), synthetic_seq.path, {})
    tum = run_sequence(get_adapter("command", **command_options("tum")), synthetic_seq.path, {})
    np.testing.assert_allclose(tum.T_world_lidar, kitti.T_world_lidar, atol=1e-6)
    assert final_errors(tum.T_world_lidar, synthetic_seq.gt)[0] < 0.3


def test_schedule_reaches_the_process(synthetic_seq: Seq, tmp_path: Path) -> None:
    """The work dir holds params.json, schedule.csv and .json with the per-frame values."""
    opts = {**command_options(), "keep_workdir": True, "workdir": str(tmp_path)}
    adapter = get_adapter("command", **opts)
    n = len(synthetic_seq)
    sched = Schedule.constant(adapter.space.defaults(), n)
    sched.values["max_correspondence_distance"][5:] = 1.0
    run_sequence(adapter, synthetic_seq.path, sched)
    (work,) = tmp_path.iterdir()
    rows = (work / "schedule.csv").read_text().splitlines()
    assert rows[0] == "frame,stamp_ns,max_correspondence_distance,downsampling_resolution"
    assert len(rows) == n + 1 and rows[6].split(",")[2] == "1.0" and rows[5].split(",")[2] == "2.0"
    js = json.loads((work / "schedule.json").read_text())
    assert js["params"]["max_correspondence_distance"][4:6] == [2.0, 1.0]
    assert json.loads((work / "params.json").read_text())["max_correspondence_distance"] == 2.0


def test_scans_not_from_a_file_are_written_for_the_process(synthetic_seq: Seq) -> None:
    adapter = get_adapter("command", **command_options())
    scans = synthetic_seq.scans[:6]
    traj = adapter.run(scans, Schedule.constant(adapter.space.defaults(), 6))
    assert len(traj) == 6 and traj.is_finite()
    assert list(traj.stamps_ns) == [s.stamp_ns for s in scans]


def test_failing_process_is_an_odometry_error(synthetic_seq: Seq, monkeypatch) -> None:
    monkeypatch.setenv("S2S_FAIL", "1")
    with pytest.raises(OdometryError, match="exited with status 3: s2s_gicp: failing on purpose"):
        run_sequence(get_adapter("command", **command_options()), synthetic_seq.path, {})


def test_hanging_process_is_killed_at_the_time_limit(synthetic_seq: Seq, monkeypatch) -> None:
    monkeypatch.setenv("S2S_SLEEP", "60")
    with pytest.raises(TrialTimeout, match="time limit of 1 s"):
        run_sequence(get_adapter("command", **command_options()), synthetic_seq.path, {},
                     time_limit_s=1.0)


@pytest.mark.parametrize("fmt", ["kitti", "tum"])
def test_lost_frames_are_an_odometry_error(fmt: str, synthetic_seq: Seq, monkeypatch) -> None:
    monkeypatch.setenv("S2S_DROP", "1")
    n = len(synthetic_seq)
    msg = f"has {n - 1} poses for {n} frames" if fmt == "kitti" else f"no pose for frame {n - 1}"
    with pytest.raises(OdometryError, match=msg):
        run_sequence(get_adapter("command", **command_options(fmt)), synthetic_seq.path, {})


def test_bad_command_options_are_config_errors(tmp_path: Path, synthetic_seq: Seq) -> None:
    with pytest.raises(ConfigError, match="unknown placeholder"):
        get_adapter("command", command=["x", "{sequnce}"],
                    space=str(SCRIPTS / "s2s_gicp_space.yaml"))
    with pytest.raises(ConfigError, match="no such parameter space file"):
        get_adapter("command", command="x {out}", space=str(tmp_path / "nope.yaml"))
    bad = tmp_path / "space.json"
    bad.write_text(json.dumps([{"name": "a", "low": 0, "high": 1, "default": 5}]))
    with pytest.raises(ConfigError, match="default 5 outside"):
        get_adapter("command", command="x {out}", space=str(bad))
    adapter = get_adapter("command", command=[str(tmp_path / "missing-binary"), "{out}"],
                          space=[{"name": "a", "low": 0, "high": 1, "default": 0.5}])
    assert adapter.space.names == ["a"]
    with pytest.raises(ConfigError, match="cannot run"):
        adapter.run(synthetic_seq.scans[:2], Schedule.constant({"a": 0.5}, 2))


def test_soft_time_limit_of_in_process_adapters(synthetic_seq: Seq) -> None:
    with pytest.raises(TrialTimeout, match="ndt: time limit"):
        run_sequence(get_adapter("ndt"), synthetic_seq.path, {}, time_limit_s=1e-9)


def test_check_trajectory_rejects_nan_and_lost_frames() -> None:
    T = np.tile(np.eye(4), (5, 1, 1))
    stamps = np.arange(5, dtype=np.int64) * 100
    check_trajectory(Trajectory(np.arange(5), stamps, T), stamps, "x")
    T[3, 0, 3] = np.nan
    with pytest.raises(OdometryError, match="x: non-finite pose at frame 3"):
        check_trajectory(Trajectory(np.arange(5), stamps, T), stamps, "x")
    with pytest.raises(OdometryError, match="x: returned 4 poses for 5 frames"):
        check_trajectory(Trajectory(np.arange(4), stamps[:4], T[:4]), stamps, "x")
    T = np.tile(np.eye(4), (5, 1, 1))
    T[2, :3, :3] *= 2
    with pytest.raises(OdometryError, match="frame 2 is not a rigid transform"):
        check_trajectory(Trajectory(np.arange(5), stamps, T), stamps, "x")


COUNT_SCANS = """
import sys, pathlib
import numpy as np
scans, layout, out = pathlib.Path(sys.argv[1]), sys.argv[2], sys.argv[3]
files = sorted((scans / 'velodyne').glob('*.bin') if layout == 'kitti' else scans.glob('*.pcd'))
times = np.loadtxt(scans / 'times.txt', ndmin=1)
assert len(files) == len(times), (len(files), len(times))
with open(out, 'w') as fh:
    for k, t in enumerate(times):
        fh.write('%.9f %d 0 0 0 0 0 1\\n' % (t, k))
"""
"""A tool that reads the scans folder with numpy only and writes a TUM trajectory: x = frame,
stamped with the times.txt line (the stamps the adapter matches)."""


@pytest.mark.parametrize("layout", ["kitti", "pcd"])
def test_scans_reach_the_tool_as_kitti_or_pcd_files(layout: str, synthetic_seq: Seq,
                                                    tmp_path: Path) -> None:
    """scans: kitti | pcd hands the tool a folder of .bin or .pcd files and times.txt, the
    scans exactly (read back with adaptune's readers and open3d), stamps matched to the
    frames; scans_cache writes them once per sequence."""
    import open3d as o3d

    from pipeline.sequence import SequenceReader
    from pipeline.sources.scanfiles import read_scan

    cache = tmp_path / "cache"
    adapter = get_adapter(
        "command", command=["{python}", "-c", COUNT_SCANS, "{scans}", layout, "{out}"],
        space=[{"name": "k", "low": 0.0, "high": 1.0, "default": 0.5}], format="tum",
        scans=layout, scans_cache=str(cache))
    traj = run_sequence(adapter, synthetic_seq.path, {})
    np.testing.assert_array_equal(traj.T_world_lidar[:, 0, 3], np.arange(len(synthetic_seq)))
    (folder,) = cache.iterdir()
    files = sorted((folder / "velodyne").glob("*.bin") if layout == "kitti"
                   else folder.glob("*.pcd"))
    with SequenceReader(synthetic_seq.path) as reader:
        assert len(files) == len(reader)
        for k in (0, len(reader) - 1):
            np.testing.assert_array_equal(read_scan(files[k]).points, reader[k].points_lidar)
        if layout == "pcd":
            cloud = o3d.t.io.read_point_cloud(str(files[3]))
            np.testing.assert_array_equal(cloud.point.positions.numpy(), reader[3].xyz)
    written = files[0].stat().st_mtime_ns
    run_sequence(adapter, synthetic_seq.path, {})
    assert [p.name for p in cache.iterdir()] == [folder.name]
    assert files[0].stat().st_mtime_ns == written  # read again, not written again
