"""The "Your own data" commands of docs/usage.md, run exactly as written (issue 14): the shell
block is read from the page and every `adaptune` line in it runs, in order, in a folder holding
what the lines name, made from the real KITTI 04 scans: scans/ (PCD files), poses.txt (KITTI's
camera-frame poses) and calib.txt, a ROS 1 bag run.bag (/points, Odometry on /odom), a ROS 2
bag run_ros2/ (PoseStamped on /ground_truth; sqlite3, then again with mcap storage); the KITTI
root's path is the one word replaced. If the page changes, this test runs the new lines."""

from __future__ import annotations

import shlex
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.source_inputs import KittiFrames, load_kitti, write_bag, write_pcd

from pipeline.sequence import SequenceReader
from stages.cli import main

USAGE = Path(__file__).resolve().parents[2] / "docs" / "usage.md"
USAGE_ROOT = "/data/kitti/dataset"


def usage_commands() -> list[list[str]]:
    """The argument lists of the `adaptune` lines of the "Your own data" shell block."""
    section = USAGE.read_text().split("\n## Your own data\n", 1)[1]
    block = section.split("```sh\n", 1)[1].split("```", 1)[0]
    return [shlex.split(line, comments=True)[1:] for line in block.splitlines()
            if line.startswith("adaptune ")]


@pytest.fixture(scope="module")
def frames(kitti_root: Path) -> KittiFrames:
    """KITTI 04 frames 0-9 (11.9 m), every second point."""
    kf = load_kitti(kitti_root, "04", 10)
    return replace(kf, points=[p[::2].copy() for p in kf.points])


def inputs(folder: Path, kf: KittiFrames, kitti_root: Path, ros2_storage: str) -> None:
    """What the page's lines name, in ``folder``."""
    scans = folder / "scans"
    scans.mkdir()
    for k, pts in enumerate(kf.points):  # plain string order would put full7 last
        write_pcd(scans / f"full{7 * k}.pcd", pts)
    shutil.copy(kitti_root / "poses" / "04.txt", folder / "poses.txt")
    shutil.copy(kitti_root / "sequences" / "04" / "calib.txt", folder / "calib.txt")
    write_bag(folder / "run.bag", kf, ros=1, gt="odom", cloud_topic="/points")
    write_bag(folder / "run_ros2", kf, ros=2, storage=ros2_storage, gt="pose")


def check_sequence(path: Path, kf: KittiFrames, points: list[np.ndarray]) -> None:
    with SequenceReader(path) as r:
        assert len(r) == len(kf.points)
        np.testing.assert_allclose(r.ground_truth(), kf.T_world_lidar, atol=1e-6)
        for k in (0, 4, 9):
            np.testing.assert_array_equal(r[k].points_lidar, points[k])


def test_the_usage_commands_run_as_written(frames: KittiFrames, kitti_root: Path,
                                            tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                            ) -> None:
    commands = usage_commands()
    kinds = [c[1] if c[0] in ("ingest", "metric") else c[0] for c in commands]
    assert kinds == ["folder", "rosbag", "rosbag", "kitti", "run", "rte"], commands
    assert commands[1][2].endswith(".bag") and commands[2][2].endswith("/")  # ROS 1, ROS 2
    monkeypatch.chdir(tmp_path)
    inputs(tmp_path, frames, kitti_root, "sqlite3")
    full = load_kitti(kitti_root, "04", 10).points
    for args in commands:
        args = [str(kitti_root) if a == USAGE_ROOT else a for a in args]
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, (args, result.output)
        if args[0] == "ingest":
            out = Path(args[args.index("--out") + 1])
            check_sequence(out, frames, full if args[1] == "kitti" else frames.points)
            if args[1] == "folder":
                with SequenceReader(out) as r:
                    assert r.info.sensor == args[args.index("--sensor") + 1]
        elif args[0] == "metric":
            lines = result.stdout.splitlines()
            assert lines[0].startswith("10 frames") and "RTE  L = " in lines[1], lines
            assert " 0 start frames" not in lines[1]
    # the same ROS 2 line on a bag with mcap storage
    shutil.rmtree("run_ros2")
    write_bag(tmp_path / "run_ros2", frames, ros=2, storage="mcap", gt="pose")
    assert [p.suffix for p in Path("run_ros2").iterdir()].count(".mcap") == 1
    result = CliRunner().invoke(main, commands[2])
    assert result.exit_code == 0, result.output
    check_sequence(Path(commands[2][commands[2].index("--out") + 1]), frames, frames.points)
