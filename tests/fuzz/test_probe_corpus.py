"""The probe corpus of issue 32: one test per reproducible case of the audit, by family (each
failed before its fix). The faults that need real processes or devices live beside their kind
(tests/tuning/test_orphans.py, tests/test_outputs.py, tests/evaluation/test_query.py).

Every refusal is one line ``adaptune: error: ...`` naming the value and the rule, exit code 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result

from pipeline.sequence import SequenceInfo, SequenceWriter
from pipeline.trajectory import Trajectory, write_trajectory
from stages.cli import main


def invoke(args: list[str], input: str | None = None) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args], input=input)


def fails(args: list[str], *needles: str) -> str:
    """Run ``adaptune ARGS``: exit 1, one ``adaptune: error:`` line holding every needle."""
    result = invoke(args)
    assert result.exit_code == 1, (result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def straight_sequence(path: Path, frames: int = 12, step_m: float = 1.0) -> Path:
    """``frames`` scans of 5 points, the ground truth ``step_m`` apart along a gentle curve."""
    with SequenceWriter(path, SequenceInfo(name=path.stem)) as w:
        for k in range(frames):
            T = np.eye(4)
            T[:2, 3] = k * step_m, 0.01 * k * k
            w.add(100_000_000 * k, np.ones((5, 3), np.float32) * k, T)
    return path


# ------------------------------------------------------------------------------- Readers


def trajectory_file(path: Path, sequence: Path, frames: list[int],
                    T: np.ndarray | None = None) -> Path:
    n = len(frames)
    T = np.tile(np.eye(4), (n, 1, 1)) if T is None else T
    if n:
        T[:, 0, 3] = np.arange(n)
    write_trajectory(path, Trajectory(np.array(frames, np.int32),
                                      100_000_000 * np.array(frames, np.int64), T),
                     {"sequence": str(sequence)})
    return path


@pytest.mark.parametrize("case, frames, scale, needle", [
    ("no rows (case 7: IndexError)", [], 1.0, "has no poses"),
    ("a rotation that is not one (case 6: scored 436 %)", [0, 1, 2, 3], 2.0,
     "not a rotation matrix"),
    ("duplicate frame numbers (case 6: exported)", [0, 1, 1, 2], 1.0,
     "frame numbers must increase"),
])
def test_a_trajectory_no_run_gives_is_refused(tmp_path: Path, case: str, frames: list[int],
                                             scale: float, needle: str) -> None:
    seq = straight_sequence(tmp_path / "s.mcap")
    T = np.tile(np.eye(4), (len(frames), 1, 1))
    T[:, :3, :3] *= scale
    traj = trajectory_file(tmp_path / "t.parquet", seq, frames, T)
    fails(["export", traj, "--format", "kitti", "--out", tmp_path / "o.txt"], needle)
    fails(["metric", "rte", seq, traj, "--length", "2"], needle)
    assert not (tmp_path / "o.txt").exists()


@pytest.mark.timeout(60, method="signal")
def test_a_kitti_pose_file_that_is_a_fifo_is_an_error(tmp_path: Path) -> None:
    """Case 5: ROOT/poses/NN.txt a FIFO gave "ground truth: no" and exit 0 (a missing pose
    file is optional; one that is there but no regular file is not)."""
    import os

    from test_fuzz_cli import kitti_layout

    paths = kitti_layout(tmp_path / "kitti")
    paths["poses"].unlink()
    os.mkfifo(paths["poses"])
    out = tmp_path / "00.mcap"
    fails(["ingest", "kitti", tmp_path / "kitti", "00", "--out", out], str(paths["poses"]),
          "is not a regular file", "a FIFO")
    assert not out.exists()


def test_a_point_channel_that_declares_another_type_is_refused(tmp_path: Path) -> None:
    """Case 6: an MCAP whose /lidar/points channel declares std_msgs/String was read as
    PointCloud2 (its bytes were one)."""
    from mcap.writer import Writer
    from test_fuzz_mcap import cloud_cdr

    from pipeline.sequence import META_FRAMES, META_SEQUENCE, POINTS_TOPIC

    layout = {"fields": [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)],
              "height": 1, "width": 1, "point_step": 16, "row_step": 16, "big": False,
              "data": np.ones(4, "<f4").tobytes()}
    path = tmp_path / "s.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="probe")
        schema = w.register_schema("std_msgs/String", "ros2msg", b"string data")
        channel = w.register_channel(POINTS_TOPIC, "cdr", schema)
        w.add_message(channel, log_time=0, publish_time=0, data=cloud_cdr(0, layout))
        w.add_metadata(META_SEQUENCE, SequenceInfo("s", frame_count=1).to_record())
        w.add_metadata(META_FRAMES, {"stamps_ns": "0"})
        w.finish()
    fails(["info", path], "channel /lidar/points declares std_msgs/String",
          "sensor_msgs/msg/PointCloud2")


def test_info_checks_the_chunk_crcs(tmp_path: Path) -> None:
    """Case 6: `info` accepted a chunk with a bad CRC (it read the scans without checking)."""
    from mcap.reader import make_reader

    path = tmp_path / "s.mcap"
    with SequenceWriter(path, SequenceInfo(name="s")) as w:  # no ground truth: only scans
        for k in range(3):
            w.add(10 + k, np.full((5, 3), k, np.float32))
    with open(path, "rb") as fh:
        first = make_reader(fh).get_summary().chunk_indexes[0].chunk_start_offset
    data = bytearray(path.read_bytes())
    assert data[first] == 0x06  # a Chunk record: opcode, length, start, end, size, crc
    data[first + 33] ^= 0xFF
    path.write_bytes(bytes(data))
    fails(["info", path], "crc validation failed")


def test_a_bad_calibration_is_named_as_such(tmp_path: Path) -> None:
    """Case 9: a calib.txt Tr that is no rotation was reported as "ground truth pose 0" of
    the first .bin."""
    from test_fuzz_cli import kitti_layout

    paths = kitti_layout(tmp_path / "kitti")
    paths["calib.txt"].write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 2 0 0 0 0 2 0 0 0 0 2 0\n")
    fails(["ingest", "kitti", tmp_path / "kitti", "00", "--out", tmp_path / "s.mcap"],
          f"{paths['calib.txt']}: Tr line 2", "not a rotation matrix")


def test_a_scan_rate_near_zero_is_one_line(tmp_path: Path) -> None:
    """Case 9: `ingest folder --rate 1e-12` printed a numpy warning, then a stamp error."""
    folder = tmp_path / "scans"
    folder.mkdir()
    for k in range(3):
        np.full((10, 4), k, "<f4").tofile(folder / f"{k}.bin")
    fails(["ingest", "folder", folder, "--rate", "1e-12", "--out", tmp_path / "s.mcap"],
          "--rate 1e-12 Hz", "stamp 1 is 1000000000000.0 s")


def test_bad_schedule_values_name_the_schedule(tmp_path: Path) -> None:
    """Case 9: a schedule's value out of range was reported against the sequence."""
    from pipeline.odometry.base import Schedule

    seq = straight_sequence(tmp_path / "s.mcap", frames=4)
    sched = tmp_path / "sched.parquet"
    Schedule(np.arange(4, dtype=np.int32), {"resolution": np.full(4, -5.0),
                                            "keyframe_interval": np.ones(4)},
             100_000_000 * np.arange(4, dtype=np.int64)).write(sched)
    line = fails(["run", "-a", "ndt", "--schedule", sched, seq, "--out", tmp_path / "t.parquet"],
                 "resolution must be in [1.0, 10.0], got -5.0 at frame 0")
    assert line.startswith(f"adaptune: error: {sched}: ") and f"(for {seq})" in line, line


def test_which_pose_lines_scans_take_is_said(tmp_path: Path,
                                             caplog: pytest.LogCaptureFixture) -> None:
    """Case 6: scans 1.pcd..9.pcd with a 10-line KITTI pose file took lines 2..10 (row n for
    scan n, numbered from 0 as KITTI's), one frame off from a folder numbered from 1, with no
    warning; `info` did not say which lines. Now a warning at ingest and the lines in the
    sequence's metadata, which `info` shows."""
    import json

    folder = tmp_path / "scans"
    folder.mkdir()
    for k in range(1, 10):
        np.full((10, 4), k, "<f4").tofile(folder / f"{k}.bin")
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(f"1 0 0 {0.86 * k} 0 1 0 0 0 0 1 0\n" for k in range(10)))
    out = tmp_path / "s.mcap"
    done = invoke(["ingest", "folder", folder, "--poses", poses, "--out", out])
    assert done.exit_code == 0, done.output
    assert "lines 2-10 of 10 used" in caplog.text, caplog.text  # a warning
    info = invoke(["info", "--json", out])
    assert json.loads(info.stdout)["details"]["pose_lines"] == "2-10 of 10"


# ------------------------------------------------------------------------ Params and CLI


@pytest.mark.timeout(60, method="signal")
@pytest.mark.parametrize("command", [
    ["run", "-a", "ndt", "--params", "@{p}", "{seq}", "--out", "{tmp}/t.parquet"],
    ["params", "ndt", "--params", "{p}"],
    ["trials", "{seq}", "--out", "{tmp}/out", "--params", "{p}"],
], ids=["run", "params", "trials"])
@pytest.mark.parametrize("kind", ["FIFO", "/dev/zero", "65 MiB"])
def test_a_params_file_is_a_bounded_regular_file(tmp_path: Path, command: list[str],
                                                kind: str) -> None:
    """Cases 4 and 5: `--params FIFO` hung run, params and trials; `run --params @/dev/zero`
    grew to 23 GB. One bounded reader (pipeline.io_utils.read_input): regular files of at most
    64 MiB, refused at once."""
    import os

    seq = straight_sequence(tmp_path / "s.mcap")
    p = tmp_path / "p.yaml"
    if kind == "FIFO":
        os.mkfifo(p)
    elif kind == "/dev/zero":
        p = Path("/dev/zero")
    else:
        with open(p, "wb") as fh:  # sparse: no 65 MiB written
            fh.truncate(65 << 20)
    needle = "64 MiB" if kind == "65 MiB" else "is not a regular file"
    fails([a.format(p=p, seq=seq, tmp=tmp_path) for a in command], str(p), needle)


def files_under(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


def test_names_that_would_leave_the_output_folder_are_refused(tmp_path: Path) -> None:
    """Case 3: `ingest: {train: ["../../kr/sequences/04"]}` (today a kitti source of the data
    section) wrote next to the KITTI root and index.json recorded the `..` path; `ingest --name`
    and `simulate --name` took `..` and `/`. One path guard (pipeline.io_utils.check_plain_name)
    for every name that becomes a file; no folder is made before it passed."""
    from test_fuzz_cli import kitti_layout

    kitti_layout(tmp_path / "kr")
    before = files_under(tmp_path)
    params = tmp_path / "p.yaml"
    params.write_text(f'data: {{sources: [{{kind: kitti, path: "{tmp_path / "kr"}", '
                      'sequences: ["../../kr/sequences/00"], split: train}]}\n')
    out = tmp_path / "a" / "b" / "out"
    fails(["ingest-set", "--params", params, "--out", out], "KITTI sequence",
          "plain file name", "../../kr/sequences/00")
    assert not (tmp_path / "a").exists()
    assert files_under(tmp_path) == before | {params}, "a file was written"
    fails(["ingest", "kitti", tmp_path / "kr", "00", "--name", "../x", "--out",
           tmp_path / "x.mcap"], "sequence name", "'../x'")
    fails(["simulate", "--frames", "3", "--name", "a/b", "--out", tmp_path / "y.mcap"],
          "sequence name", "'a/b'")
    seqs = tmp_path / "seqs"
    straight_sequence(seqs / "s.mcap")
    (seqs / "index.json").write_text('{"train": ["../seqs/s"]}')
    fails(["trials", "--sequences", seqs, "--out", tmp_path / "t", "-a", "ndt"],
          "index.json", "'../seqs/s'")
    assert files_under(tmp_path) == before | {params, seqs / "s.mcap", seqs / "index.json"}


def test_a_split_without_its_source_is_refused(tmp_path: Path) -> None:
    """Case 6: `ingest: {kitti_root: null, train: ["04"]}` wrote an index with no file behind
    it. In the data section a split is a property of a source: a KITTI source without its root,
    or a split list without sources, is refused before any folder is made."""
    for text, needle in [
            ('data: {sources: [{kind: kitti, path: null, sequences: ["04"], split: train}]}',
             "data.sources.0.kitti.path"),
            ('data: {splits: {train: ["04"]}}', "data.splits: unknown parameter")]:
        params = tmp_path / "p.yaml"
        params.write_text(text + "\n")
        fails(["ingest-set", "--params", params, "--out", tmp_path / "out"], needle)
        assert not (tmp_path / "out").exists()


def test_a_surrogate_k_beyond_the_rows_is_refused_when_fitting(kitti_root: Path) -> None:
    """Case 6: `surrogate.k: 1000000` wrote an artifact that `select` then refused; the fit
    refuses it with the loader's rule (pipeline.surrogates.knn.check_k)."""
    from helpers.models import synthetic_rows

    from pipeline.errors import ConfigError
    from pipeline.odometry import get_adapter
    from pipeline.surrogates.fit import SurrogateSection, fit_surrogate

    rows, _ = synthetic_rows(kitti_root, 4)
    space = get_adapter("ndt").space.to_json()
    with pytest.raises(ConfigError, match=r"surrogate\.k must be an integer in \[1, "
                       rf"{len(rows.y)}\] \(the training rows\), got 1000000"):
        fit_surrogate(rows, space, SurrogateSection(k=1_000_000, n_sobol=16, cv_max_frames=2))


def test_a_negative_trials_seed_is_refused() -> None:
    """Case 6: `trials --seed -1` was accepted (base.seed's rule, >= 0, applies to --seed)."""
    fails(["trials", "x.mcap", "--out", "o", "--seed", "-1"], "base.seed", "-1")


def test_simulate_frames_are_capped() -> None:
    """Case 4: `simulate --frames 1000000000` had no bound (MAX_FRAMES, named)."""
    fails(["simulate", "--frames", "1000000000", "--out", "x.mcap"], "[2, 100000]",
          "MAX_FRAMES", "1000000000")


def test_a_sequence_shorter_than_the_rte_length_is_refused_by_evaluate(tmp_path: Path) -> None:
    """Case 6: a validation sequence shorter than L dropped out of its split: the headline came
    from the others while the report row named all of them, and its plot read "nan %"."""
    from pipeline.errors import InputError
    from pipeline.evaluate.runs import evaluate
    from pipeline.evaluate.section import EvaluateSection

    long = straight_sequence(tmp_path / "long.mcap", frames=40)  # 39 m
    short = straight_sequence(tmp_path / "short.mcap", frames=12)  # 11 m
    with pytest.raises(InputError, match=r"short\.mcap: ground truth runs 11\.\d m, not longer "
                       r"than length_m=25\.0: no RTE segment to score"):
        evaluate([long, short], "ndt", {}, tmp_path / "adaptive", tmp_path / "out",
                 EvaluateSection(length_m=25.0))
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("address", ["tcp://", "tcp://host", "tcp://host:port", "tcp://host:0"])
def test_a_dask_address_without_a_port_is_one_line(address: str) -> None:
    """Case 7: `--dask tcp://` was distributed's ValueError traceback ("missing port")."""
    fails(["trials", "x.mcap", "--out", "o", "--dask", address], "trials.dask",
          "scheme://host:port", repr(address))


@pytest.mark.parametrize("args", [
    ["metric", "rte", "{seq}", "-", "--length", "2"],
    ["info", "-"],
    ["run", "-a", "ndt", "--params", "@-", "{seq}", "--out", "{tmp}/t.parquet"],
    ["ingest", "folder", "{tmp}", "--poses", "-", "--out", "{tmp}/x.mcap"],
    ["descriptors", "--sequences", "{tmp}", "--out", "-", "--environment", "{tmp}/e.parquet",
     "--pca", "{tmp}/pca"],
], ids=["metric rte SEQ -", "info -", "run --params @-", "--poses -", "descriptors --out -"])
def test_a_dash_is_no_file_name(tmp_path: Path, args: list[str],
                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Case 6: `export --out -` wrote a file named `-`, `metric rte seq -` scored a stale file
    of that name. `-` is stdin only for query's SQL, stdout only for the one file a command
    writes (issue 58: `export --out -` writes stdout, test_an_output_is_written_through);
    elsewhere it is refused (a file named - is ./-)."""
    seq = straight_sequence(tmp_path / "s.mcap")
    traj = trajectory_file(tmp_path / "t0.parquet", seq, [0, 1, 2])
    monkeypatch.chdir(tmp_path)
    Path("-").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 12)  # the stale file
    before = Path("-").read_bytes()
    fails([a.format(seq=seq, traj=traj, tmp=tmp_path) for a in args], "'-' (stdin, stdout)",
          "./- for a file named -")
    assert Path("-").read_bytes() == before
