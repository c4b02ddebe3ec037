"""Bad input to the readers (issue 13, items 7 and 8): each is one line naming the file and the
rule, exit 1, no output. Before these rules they were tracebacks or silently accepted."""

from __future__ import annotations

import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.source_inputs import write_pcd

from stages.cli import main


def fails(args: list[object], *fragments: str, out: Path | None = None) -> str:
    """Run the CLI: exit 1, one line ``adaptune: error: ...`` with every fragment."""
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    if out is not None:
        assert not out.exists() and not list(out.parent.glob(f".{out.name}.*"))
    return lines[0]


@pytest.fixture
def root(kitti_root: Path, tmp_path: Path) -> Path:
    """A KITTI root with the first 3 scans of sequence 04 (cut to 3000 points), its calib,
    times and poses: a copy the tests can damage."""
    src, seq = kitti_root / "sequences" / "04", tmp_path / "kitti" / "sequences" / "04"
    (seq / "velodyne").mkdir(parents=True)
    for k in range(3):
        pts = np.fromfile(src / "velodyne" / f"{k:06d}.bin", np.float32).reshape(-1, 4)
        pts[:3000].tofile(seq / "velodyne" / f"{k:06d}.bin")
    shutil.copy(src / "calib.txt", seq / "calib.txt")
    (seq / "times.txt").write_text("".join((src / "times.txt").read_text().splitlines(True)[:3]))
    (tmp_path / "kitti" / "poses").mkdir()
    lines = (kitti_root / "poses" / "04.txt").read_text().splitlines(True)[:3]
    (tmp_path / "kitti" / "poses" / "04.txt").write_text("".join(lines))
    return tmp_path / "kitti"


def kitti(root: Path, out: Path) -> list[object]:
    return ["ingest", "kitti", root, "04", "--out", out]


@pytest.mark.parametrize("times, rule", [
    ("0.0 1.0\n0.1 1.1\n0.2 1.2\n", "line 1: 2 values, a times file has one number a line"),
    ("-0.1\n0.0\n0.1\n", "out of range (stamps must be in [0, 2^31) s"),
    ("2147483648.0\n2147483648.1\n2147483648.2\n", "out of range"),
    ("1e30\n2e30\n3e30\n", "stamp 1e30 s is out of range"),  # beyond int64 ns
])
def test_times_file_rules(root: Path, tmp_path: Path, times: str, rule: str) -> None:
    path = root / "sequences" / "04" / "times.txt"
    path.write_text(times)
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), str(path), rule, out=out)


def test_rate_nan(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.mcap"
    fails(["ingest", "folder", root / "sequences" / "04" / "velodyne", "--rate", "nan",
           "--out", out], "--rate must be a finite number > 0 Hz, got nan", out=out)


def test_a_folder_named_like_a_scan(root: Path, tmp_path: Path) -> None:
    velodyne = root / "sequences" / "04" / "velodyne"
    (velodyne / "000003.bin").mkdir()
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), str(velodyne / "000003.bin"), "is not a regular file", out=out)
    fails(["ingest", "folder", velodyne, "--out", out], "000003.bin", "is not a regular file")
    (velodyne / "000003.bin").rmdir()
    os.mkfifo(velodyne / "000003.bin")  # a FIFO would block the reader
    fails(kitti(root, out), str(velodyne / "000003.bin"), "is not a regular file", out=out)


@pytest.mark.parametrize("header, rule", [
    ({"POINTS": "many"}, "PCD header POINTS must be an integer >= 0, got 'many'"),
    ({"WIDTH": "wide"}, "PCD header WIDTH must be an integer >= 0, got 'wide'"),
    ({"POINTS": "-5", "WIDTH": "-5"}, "PCD header WIDTH must be an integer >= 0, got -5"),
    ({"POINTS": "-5"}, "PCD header POINTS must be an integer >= 0, got -5"),
])
def test_pcd_header_rules(tmp_path: Path, header: dict[str, str], rule: str) -> None:
    d = tmp_path / "scans"
    d.mkdir()
    pcd = d / "0.pcd"
    write_pcd(pcd, np.ones((5, 4), np.float32))
    text = pcd.read_bytes().decode("latin-1")
    for key, value in header.items():
        text = text.replace(f"{key} 5\n", f"{key} {value}\n")
    pcd.write_bytes(text.encode("latin-1"))
    out = tmp_path / "s.mcap"
    fails(["ingest", "folder", d, "--out", out], str(pcd), rule, out=out)


def test_malformed_frame_stamps_metadata(tmp_path: Path) -> None:
    """An MCAP whose adaptune.frames metadata is not a list of ns: `info` says so."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from pipeline.sequence import META_FRAMES, SequenceInfo, SequenceWriter

    good = tmp_path / "good.mcap"
    with SequenceWriter(good, SequenceInfo(name="s")) as w:
        w.add(10, np.ones((4, 3), np.float32))
        w.add(20, np.ones((4, 3), np.float32))
    bad = tmp_path / "bad.mcap"
    with open(good, "rb") as src, open(bad, "wb") as dst:
        reader, writer = make_reader(src), Writer(dst)
        writer.start(profile="ros2", library="test")
        summary = reader.get_summary()
        for sid, schema in summary.schemas.items():
            writer.register_schema(schema.name, schema.encoding, schema.data)
            assert sid >= 1
        for ch in summary.channels.values():
            writer.register_channel(ch.topic, ch.message_encoding, ch.schema_id)
        for _, ch, msg in reader.iter_messages():
            writer.add_message(ch.id, msg.log_time, msg.data, msg.publish_time)
        for meta in reader.iter_metadata():
            record = dict(meta.metadata)
            if meta.name == META_FRAMES:
                record["stamps_ns"] = "10 twenty"
            writer.add_metadata(meta.name, record)
        writer.finish()
    fails(["info", bad], str(bad), "malformed 'adaptune.frames' metadata")


def test_simulate_negative_seed(tmp_path: Path) -> None:
    out = tmp_path / "s.mcap"
    fails(["simulate", "--seed", "-1", "--frames", "3", "--out", out],
          "seed must be an integer in [0, 2^63), got -1", out=out)


@pytest.mark.parametrize("R, det", [(np.zeros((3, 3)), "det = 0"), (2 * np.eye(3), "det = 8"),
                                    (np.diag([1.0, 1.0, -1.0]), "det = -1")])
def test_ground_truth_that_is_not_a_rotation(root: Path, tmp_path: Path, R: np.ndarray,
                                             det: str) -> None:
    poses = root / "poses" / "04.txt"
    lines = poses.read_text().splitlines()
    P = np.array(lines[1].split(), float).reshape(3, 4)
    P[:, :3] = R
    lines[1] = " ".join(f"{v:.6e}" for v in P.ravel())
    poses.write_text("\n".join(lines) + "\n")
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), f"{poses} line 2", "not a rotation matrix", det, out=out)


def test_zero_quaternion_in_a_tum_file(root: Path, tmp_path: Path) -> None:
    tum = tmp_path / "gt.tum"
    tum.write_text("0.0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 0 0\n0.2 2 0 0 0 0 0 1\n")
    out = tmp_path / "s.mcap"
    fails(["ingest", "folder", root / "sequences" / "04" / "velodyne", "--poses", tum,
           "--out", out], f"{tum} line 2", "quaternion has norm 0", out=out)


def test_random_bytes_as_a_bin_scan(root: Path, tmp_path: Path) -> None:
    """Random bytes are a multiple of 16 long, read as float32 they reach 3e38 m."""
    scan = root / "sequences" / "04" / "velodyne" / "000001.bin"
    scan.write_bytes(np.random.default_rng(7).bytes(16 * 4000))
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), str(scan), "beyond 10000 m", "not a LiDAR scan", out=out)


def test_kitti_numbering_with_a_gap(root: Path, tmp_path: Path) -> None:
    velodyne = root / "sequences" / "04" / "velodyne"
    (velodyne / "000002.bin").rename(velodyne / "000005.bin")
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), str(velodyne), "scan 2 is 000005.bin, expected 000002.bin", out=out)


def test_ground_truth_far_off_earth_and_huge_rotation_entries(root: Path, tmp_path: Path) -> None:
    """Positions of 1e300 m were accepted (a KITTI pose file; a TUM file); rotation entries of
    1e300 were refused with numpy's overflow warnings around the line."""
    poses = root / "poses" / "04.txt"
    lines = poses.read_text().splitlines()
    P = np.array(lines[1].split(), float).reshape(3, 4)
    P[0, 3] = 1e300
    lines[1] = " ".join(f"{v:.6e}" for v in P.ravel())
    poses.write_text("\n".join(lines) + "\n")
    out = tmp_path / "s.mcap"
    fails(kitti(root, out), "ground-truth position", "beyond 1e+08 m", out=out)
    P[0, 3], P[0, 0] = 0.0, 1e300
    lines[1] = " ".join(f"{v:.6e}" for v in P.ravel())
    poses.write_text("\n".join(lines) + "\n")
    fails(kitti(root, out), f"{poses} line 2", "not a rotation matrix", out=out)
    P[1, 1] = P[2, 2] = 1e300  # det 1e900: it overflowed with a warning in the error message
    lines[1] = " ".join(f"{v:.6e}" for v in P.ravel())
    poses.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fails(kitti(root, out), f"{poses} line 2", "not a rotation matrix", "det = inf",
              out=out)
    tum = tmp_path / "gt.tum"
    tum.write_text("0.0 0 0 0 0 0 0 1\n0.1 0 0 -2e9 0 0 0 1\n0.2 0 0 0 0 0 0 1\n")
    fails(["ingest", "folder", root / "sequences" / "04" / "velodyne", "--poses", tum,
           "--out", out], f"{tum}: pose 1 is at [0.0, 0.0, -2000000000.0] m", out=out)


def test_a_times_file_with_a_byte_order_mark(root: Path, tmp_path: Path) -> None:
    """Editors on Windows start UTF-8 files with a BOM: read, not refused."""
    times = root / "sequences" / "04" / "times.txt"
    times.write_bytes(b"\xef\xbb\xbf" + times.read_bytes().replace(b"\n", b"\r\n"))
    out = tmp_path / "s.mcap"
    result = CliRunner().invoke(main, [str(a) for a in kitti(root, out)])
    assert result.exit_code == 0, result.output


@pytest.mark.timeout(60, method="signal")
@pytest.mark.parametrize("args, kind", [
    (["ingest", "folder", "{velodyne}", "--poses", "{fifo}", "--out", "{out}"], "pose file"),
    (["ingest", "folder", "{velodyne}", "--times", "{fifo}", "--out", "{out}"], "times file"),
    (["ingest", "kitti", "{root}", "04", "--calib", "{fifo}", "--out", "{out}"], None),
    (["ingest", "mcap", "{fifo}", "--out", "{out}"], "MCAP file"),
    (["info", "{fifo}"], "sequence file"),
    (["export", "{fifo}", "--format", "tum", "--out", "{out}"], "trajectory file"),
    (["metric", "rte", "{fifo}", "{fifo}", "--length", "5"], "pose file"),
    (["query", "--db", "{fifo}", "SELECT 1"], "database"),
])
def test_a_fifo_in_place_of_an_input_file(root: Path, tmp_path: Path, args: list[str],
                                          kind: str | None) -> None:
    """Named as what it is, not as missing ("no such pose file"), and never waited on."""
    import os

    fifo = tmp_path / "in.fifo"
    os.mkfifo(fifo)
    names = {"velodyne": root / "sequences" / "04" / "velodyne", "fifo": fifo, "root": root,
             "out": tmp_path / "o.out"}
    if kind is None:  # kitti has no --calib: its calib.txt is the FIFO
        calib = root / "sequences" / "04" / "calib.txt"
        calib.unlink()
        os.mkfifo(calib)
        args = args[:4] + args[6:]
        fifo, kind = calib, "calibration file"
    fails([a.format(**names) for a in args], str(fifo), f"is not a regular file (a {kind}")
