"""The probe corpus of issues 32 and 58: one test per reproducible case of the audits, by family
(each failed before its fix, but for the read-only folder, which held, and the CRC case, which
pins a documented decision). The faults that need real processes or devices live beside their kind
(tests/tuning/test_orphans.py, tests/test_outputs.py, tests/evaluation/test_query.py).

Every refusal is one line ``adaptune: error: ...`` naming the value and the rule, exit code 1.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result

from pipeline.errors import OutputError
from pipeline.io_utils import atomic_path
from pipeline.sequence import SequenceInfo, SequenceReader, SequenceWriter
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


# ----------------------------------------------- Issue 58: outputs that are no regular file
# The audit of main@8fd4b99 (399 probes): an output that is a device or FIFO was replaced by a
# regular file (as root, `query --out /dev/full` replaced the system's /dev/full). Every
# device and FIFO here is one the test makes itself, never the system's.

NULL_DEVICE = (1, 3)
"""Linux's null device (major, minor), as `mknod NODE c 1 3` makes it."""
FULL_DEVICE = (1, 7)
"""Linux's full device: every write fails with ENOSPC."""
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="mknod needs root (CI runs as root)")
READER_TIMEOUT_S = 600
"""How long a FIFO's reader waits for its writer to end (generous: a loaded machine)."""


def make_device(path: Path, device: tuple[int, int] = NULL_DEVICE, *,
                block: bool = False) -> Path:
    """A device node of our own at ``path`` (`mknod path c|b MAJOR MINOR`)."""
    kind = stat.S_IFBLK if block else stat.S_IFCHR
    os.mknod(path, kind | 0o666, os.makedev(*device))
    return path


def is_device(path: Path, device: tuple[int, int] = NULL_DEVICE) -> bool:
    st = os.stat(path)
    return stat.S_ISCHR(st.st_mode) and (os.major(st.st_rdev), os.minor(st.st_rdev)) == device


class FifoReader:
    """Reads everything written to the FIFO ``path`` in a thread (the writer would wait for a
    reader forever otherwise); ``bytes()`` after the writer ended. A writer that never came is
    stood in for, through a hard link to the FIFO kept elsewhere (the path may have been
    replaced by then: the bug), so the thread always ends."""

    def __init__(self, path: Path) -> None:
        import tempfile

        self.path = path
        self.keep = Path(tempfile.mkdtemp(dir=path.parent.parent)) / "fifo"
        os.link(path, self.keep)
        self.data: list[bytes] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        with open(self.keep, "rb") as fh:
            self.data.append(fh.read())

    def bytes(self) -> bytes | None:
        """What the writer wrote; None when no writer opened the FIFO."""
        import shutil

        self.thread.join(timeout=1.0)
        stood_in = False
        if self.thread.is_alive() and not self.data:
            with contextlib.suppress(OSError):  # a reader still waits: no writer came
                os.close(os.open(self.keep, os.O_WRONLY | os.O_NONBLOCK))
                stood_in = True
        self.thread.join(timeout=READER_TIMEOUT_S)
        assert not self.thread.is_alive(), "the FIFO's reader never ended"
        shutil.rmtree(self.keep.parent)
        return None if stood_in or not self.data else self.data[0]


@pytest.fixture(scope="module")
def out_inputs(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> dict[str, Path]:
    """The inputs of every command that writes one file: a sequence of real KITTI scans, a
    trajectory of it, a model, a results database, a scan folder, a KITTI layout, a bag."""
    import duckdb
    from helpers.models import build_model, write_tiny_sequence
    from helpers.source_inputs import load_kitti, write_bag
    from test_fuzz_cli import kitti_layout

    root = tmp_path_factory.mktemp("out_inputs")
    seq = root / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=4)
    with SequenceReader(seq) as reader:
        stamps = reader.stamps_ns.copy()
    traj = root / "t.parquet"
    write_trajectory(traj, Trajectory(np.arange(4, dtype=np.int32), stamps,
                                      np.tile(np.eye(4), (4, 1, 1))), {"sequence": str(seq)})
    db = root / "r.duckdb"
    with duckdb.connect(str(db)) as con:
        con.execute("CREATE TABLE t AS SELECT range AS x FROM range(10)")
    scans = root / "scans"
    scans.mkdir()
    for k in range(3):
        np.full((10, 4), k, "<f4").tofile(scans / f"{k}.bin")
    kitti_layout(root / "kitti")
    return {"seq": seq, "traj": traj, "db": db, "scans": scans, "kitti": root / "kitti",
            "model": build_model(root / "model", kitti_root),
            "bag": write_bag(root / "a.bag", load_kitti(kitti_root, "04", n=3), ros=1)}


OUT_COMMANDS: dict[str, tuple[list[str], bytes]] = {
    # command -> (its arguments but --out, how its output starts)
    "export": (["export", "{traj}", "--format", "kitti"], b"1.0000"),
    "export --ground-truth": (["export", "{seq}", "--ground-truth", "--format", "tum"], b"1.0"),
    "run": (["run", "-a", "ndt", "{seq}"], b"PAR1"),
    "simulate": (["simulate", "--frames", "3"], b"\x89MCAP0\r\n"),
    "plot-world": (["plot-world", "--frames", "3"], b"\x89PNG"),
    "ingest folder": (["ingest", "folder", "{scans}"], b"\x89MCAP0\r\n"),
    "ingest kitti": (["ingest", "kitti", "{kitti}", "00"], b"\x89MCAP0\r\n"),
    "ingest mcap": (["ingest", "mcap", "{seq}"], b"\x89MCAP0\r\n"),
    "ingest rosbag": (["ingest", "rosbag", "{bag}"], b"\x89MCAP0\r\n"),
    "select": (["select", "{model}", "{seq}"], b"PAR1"),
    "live": (["live", "{model}", "{seq}"], b"\x89MCAP0\r\n"),
    "query": (["query", "--db", "{db}", "SELECT * FROM t", "--format", "csv"], b"\"x\"\n0\n"),
}
"""Every command that takes --out FILE (rte's --db and descriptors' two files go through the
same writer, atomic_path; test_folder_outputs_refuse_what_is_no_folder has the folders)."""
SAME_BYTES = set(OUT_COMMANDS) - {"simulate"}
"""Commands whose two runs write the same bytes (simulate's MCAP differs in a byte)."""


def out_args(command: str, inputs: dict[str, Path], out: Path | str) -> list[str]:
    args, _ = OUT_COMMANDS[command]
    return [a.format(**inputs) for a in args] + ["--out", str(out)]


def no_temporaries(folder: Path) -> bool:
    """Nothing of an output's temporaries left in ``folder`` nor spooled in $TMPDIR by us."""
    import tempfile

    mine = f".adaptune-out.{os.getpid()}."
    return (not [p for p in folder.iterdir() if p.name.endswith((".tmp", ".old"))]
            and not [p for p in Path(tempfile.gettempdir()).iterdir()
                     if p.name.startswith(mine)])


@pytest.mark.timeout(900, method="signal")
@pytest.mark.parametrize("command", sorted(OUT_COMMANDS))
def test_an_output_fifo_or_stdout_is_written_through(tmp_path: Path, command: str,
                                                     out_inputs: dict[str, Path],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 58, 1: `--out FIFO` (directly, or through a symlink) ended in a regular file
    where the FIFO was, exit 0; `-` was refused (export) or a file named -. Now the finished
    bytes go through the FIFO, in order, and to stdout for `-`, the same bytes."""
    monkeypatch.chdir(tmp_path)  # no ./params.yaml: every section at its defaults
    _, magic = OUT_COMMANDS[command]
    streamed = invoke(out_args(command, out_inputs, "-"))
    assert streamed.exit_code == 0, (streamed.output, streamed.exception)
    assert streamed.stdout_bytes.startswith(magic), streamed.stdout_bytes[:40]
    assert not Path("-").exists()
    if command == "simulate":  # named after its world, not after the output "-"
        (tmp_path / "got.mcap").write_bytes(streamed.stdout_bytes)
        with SequenceReader(tmp_path / "got.mcap") as reader:
            assert reader.info.name == "cave" and len(reader) == 3
        (tmp_path / "got.mcap").unlink()
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    link = tmp_path / "link"
    link.symlink_to(fifo)
    for out in (fifo, link):
        reader = FifoReader(fifo)
        done = invoke(out_args(command, out_inputs, out))
        got = reader.bytes()
        assert done.exit_code == 0, (done.output, done.exception)
        assert got is not None and got.startswith(magic), (got or b"")[:40]
        if command in SAME_BYTES:
            assert got == streamed.stdout_bytes
        assert stat.S_ISFIFO(os.stat(fifo).st_mode) and link.is_symlink()
    assert no_temporaries(tmp_path)


@needs_root
@pytest.mark.parametrize("command", sorted(OUT_COMMANDS))
def test_an_output_device_is_written_through(tmp_path: Path, command: str,
                                             out_inputs: dict[str, Path],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 58, 1: `export ... --out NODE` with NODE a null device (`mknod NODE c 1 3`)
    exited 0 and left NODE a 72 kB regular file. Now NODE, and a symlink to it, stay what
    they are: the bytes go through to the device."""
    monkeypatch.chdir(tmp_path)
    node = make_device(tmp_path / "null")
    link = tmp_path / "link"
    link.symlink_to(node)
    for out in (node, link):
        done = invoke(out_args(command, out_inputs, out))
        assert done.exit_code == 0, (done.output, done.exception)
        assert is_device(node) and link.is_symlink()
    assert no_temporaries(tmp_path)


@needs_root
def test_a_full_device_is_one_line_and_stays_a_device(tmp_path: Path,
                                                      out_inputs: dict[str, Path]) -> None:
    """Issue 58, 1: as root `query --out /dev/full` replaced the system's /dev/full with a
    regular file. A full device of our own: one line (ENOSPC), the node intact."""
    node = make_device(tmp_path / "full", FULL_DEVICE)
    fails(out_args("query", out_inputs, node), f"{node}: cannot write the output",
          "No space left on device")
    assert is_device(node, FULL_DEVICE) and no_temporaries(tmp_path)


@needs_root
def test_a_block_device_is_no_output(tmp_path: Path, out_inputs: dict[str, Path]) -> None:
    """Writing a file through to a disk is never what `--out` meant: a block device node
    (of a loop device that does not exist) is refused, nothing written to it."""
    node = make_device(tmp_path / "disk", (7, 255), block=True)
    fails(out_args("export", out_inputs, node), f"{node}: is a block device")
    assert stat.S_ISBLK(os.stat(node).st_mode) and no_temporaries(tmp_path)


@pytest.mark.timeout(300, method="signal")
def test_an_output_socket_gets_the_bytes(tmp_path: Path, out_inputs: dict[str, Path]) -> None:
    """A Unix socket a process listens on, given as --out: the bytes go to it (the path was
    replaced by a regular file)."""
    import socket

    path = tmp_path / "sock"
    got: list[bytes] = []
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(str(path))
        server.listen(1)
        server.settimeout(READER_TIMEOUT_S)

        def accept() -> None:
            conn, _ = server.accept()
            with conn:
                got.append(b"".join(iter(lambda: conn.recv(1 << 16), b"")))

        thread = threading.Thread(target=accept, daemon=True)
        thread.start()
        done = invoke(out_args("export", out_inputs, path))
        thread.join(timeout=READER_TIMEOUT_S)
    assert done.exit_code == 0, done.output
    assert got and got[0].startswith(b"1.0000") and len(got[0].splitlines()) == 4
    assert stat.S_ISSOCK(os.lstat(path).st_mode)


def test_a_failed_command_writes_nothing_through(tmp_path: Path) -> None:
    """The bytes go through only once the writer succeeded: a failure writes nothing to the
    FIFO (its reader sees no writer) and leaves no spool file."""
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    reader = FifoReader(fifo)
    with pytest.raises(RuntimeError, match="boom"), atomic_path(fifo) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("boom")
    assert reader.bytes() is None
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and no_temporaries(tmp_path)


def test_a_symlink_to_a_file_stays_a_symlink(tmp_path: Path, out_inputs: dict[str, Path]
                                             ) -> None:
    """Issue 58, 1: an output that is a symlink to a regular file: the target is replaced
    atomically, the link stays (it was replaced by a regular file, the target left stale)."""
    target = tmp_path / "real" / "poses.txt"
    target.parent.mkdir()
    target.write_text("old\n")
    link = tmp_path / "poses.txt"
    link.symlink_to(target)
    done = invoke(out_args("export", out_inputs, link))
    assert done.exit_code == 0, done.output
    assert link.is_symlink() and link.resolve() == target.resolve()
    assert target.read_text().startswith("1.0000") and len(target.read_text().splitlines()) == 4
    assert no_temporaries(tmp_path) and no_temporaries(target.parent)


# -------------------------------------------------- Folders: symlinks, devices, read-only


def test_an_output_folder_that_is_a_symlink_stays_one(tmp_path: Path, kitti_root: Path) -> None:
    """The new probe family: an output folder that is a symlink to a folder (`model/` on
    another disk). atomic_dir renamed the link aside and put a folder in its place (the
    target kept the stale model; the link was left as `.model.<pid>.<hex>.old`). Now the
    target is replaced and the link stays: the library's writer and a command's."""
    from helpers.models import write_tiny_sequence

    from pipeline.io_utils import atomic_dir

    target = tmp_path / "disk" / "model"
    target.mkdir(parents=True)
    (target / "stale").write_text("x")
    link = tmp_path / "model"
    link.symlink_to(target, target_is_directory=True)
    with atomic_dir(link) as tmp:
        (tmp / "f").write_text("new")
    assert link.is_symlink() and sorted(p.name for p in target.iterdir()) == ["f"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["disk", "model"]
    seqs = tmp_path / "seqs"  # `descriptors --pca LINK`: the PCA folder, written by atomic_dir
    seqs.mkdir()
    for name in ("a", "b"):
        write_tiny_sequence(seqs / f"{name}.mcap", kitti_root, "04", n=3)
    (seqs / "index.json").write_text('{"train": ["a", "b"]}')
    pca = tmp_path / "pca"
    pca.symlink_to(target, target_is_directory=True)
    (tmp_path / "p.yaml").write_text("descriptors: {pca_dim: 2}\n")
    done = invoke(["descriptors", "--sequences", seqs, "--out", tmp_path / "d.parquet",
                   "--environment", tmp_path / "e.parquet", "--pca", pca,
                   "--params", tmp_path / "p.yaml"])
    assert done.exit_code == 0, (done.output, done.exception)
    assert pca.is_symlink() and (target / "pca.json").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert not [p for p in target.parent.iterdir() if p.name.startswith(".")]


FOLDER_OUT_COMMANDS = {
    "simulate-set": ["simulate-set", "--out", "{out}"],
    "ingest-set": ["ingest-set", "--out", "{out}"],
    "tuning-suite": ["tuning-suite", "--out", "{out}"],
    "trials": ["trials", "{seq}", "-a", "ndt", "--iterations", "1", "--length-m", "0.5",
               "--out", "{out}"],
}
"""Folder outputs that are refused before any work when --out is no folder (the writers of
whole folders, atomic_dir, are the library test below)."""


@pytest.mark.parametrize("kind", ["FIFO", "device"])
@pytest.mark.parametrize("command", sorted(FOLDER_OUT_COMMANDS))
def test_folder_outputs_refuse_what_is_no_folder(tmp_path: Path, command: str, kind: str,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A FIFO or a device given as an output folder: one line naming what it is, the node
    intact (a device needs root: skipped without)."""
    from pipeline.io_utils import atomic_dir

    if kind == "device" and os.geteuid() != 0:
        pytest.skip("mknod needs root (CI runs as root)")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    os.mkfifo(out) if kind == "FIFO" else make_device(out)
    seq = straight_sequence(tmp_path / "s.mcap")
    what = "a FIFO" if kind == "FIFO" else "a device"
    fails([a.format(out=out, seq=seq) for a in FOLDER_OUT_COMMANDS[command]], str(out), what)
    with pytest.raises(OutputError, match=f"is {what}; the output must be a folder"):
        atomic_dir(out).__enter__()
    assert (stat.S_ISFIFO if kind == "FIFO" else stat.S_ISCHR)(os.stat(out).st_mode)


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[list[str]]:
    """Run ``adaptune`` with ``folder`` read-only: as root a private read-only bind mount of it
    (`unshare -m`: the mount lives and dies with the one process; root's writes ignore
    permission bits), as a user its bits 0555. Yields the command prefix to run under."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield [sys.executable, "-m", "stages.cli"]
        finally:
            folder.chmod(0o755)
        return
    import shutil

    if shutil.which("unshare") is None:
        pytest.skip("unshare (util-linux) is not installed")
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"no private mount namespace here: {probe.stderr.decode().strip()}")
    script = ('mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" "$0" && '
              'exec "$@"')
    yield ["unshare", "-m", "sh", "-c", script, str(folder), sys.executable, "-m", "stages.cli"]


@pytest.mark.timeout(300, method="signal")
def test_a_read_only_output_folder_is_one_line(tmp_path: Path,
                                               out_inputs: dict[str, Path]) -> None:
    """The new probe family: a read-only folder. An output there is one line naming it and
    the reason, nothing is written and nothing left; a FIFO there is still written through (no
    temporary is made beside it). Root ignores permission bits, so for root the folder is on a
    read-only mount (design.md, "Contracts")."""
    import shutil

    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "poses.txt").write_text("old\n")
    os.mkfifo(folder / "out.fifo")
    reader = FifoReader(folder / "out.fifo")
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    with read_only(folder) as prefix:
        done = [subprocess.run([*prefix, *out_args("export", out_inputs, folder / name)],
                               capture_output=True, cwd=repo, env=env, timeout=240)
                for name in ("poses.txt", "new.txt", "out.fifo")]
    got = reader.bytes()
    for run_, reason in zip(done[:2], ("poses.txt", "new.txt"), strict=True):
        lines = run_.stderr.decode().strip().splitlines()
        assert run_.returncode == 1 and len(lines) == 1, run_.stderr.decode()
        assert f"{folder / reason}: cannot write" in lines[0], lines
        assert ("Read-only file system" in lines[0] or "Permission denied" in lines[0]), lines
    assert done[2].returncode == 0, done[2].stderr.decode()
    assert got is not None and got.startswith(b"1.0000")
    assert (folder / "poses.txt").read_text() == "old\n"
    assert sorted(p.name for p in folder.iterdir()) == ["out.fifo", "poses.txt"]
    shutil.rmtree(folder)


# --------------------------------------------------------------- Issue 58: names, nesting


def test_an_output_name_past_the_limit_is_one_line(tmp_path: Path, out_inputs: dict[str, Path]
                                                   ) -> None:
    """Issue 58, 3: an output name of 300 characters was `OSError: [Errno 36] File name too
    long` from io_utils.refuse_input_as_output. A name past 223 bytes (the file system's 255,
    less the temporary's 32) is one line naming the limit; so is an input's past 255, and a
    sequence name past 200 (the files named after it need the room)."""
    long = tmp_path / ("a" * 300)
    fails(out_args("export", out_inputs, long), "a name of 300 bytes", "255")
    fails(out_args("export", out_inputs, tmp_path / ("b" * 240)), "a name of 240 bytes",
          "the 223 an output's name may have")
    fails(["export", long, "--format", "kitti", "--out", tmp_path / "x.txt"],
          "a name of 300 bytes", "the 255 of a file name")
    done = invoke(out_args("export", out_inputs, tmp_path / ("c" * 223)))
    assert done.exit_code == 0, done.output
    assert not (tmp_path / "x.txt").exists()
    for command in (["simulate", "--frames", "3"], ["ingest", "mcap", out_inputs["seq"]]):
        # a sequence's name becomes files later (<name>.mcap, sequence=<name>/): at most 200
        fails([*command, "--name", "n" * 201, "--out", tmp_path / "s.mcap"],
              "the sequence name must be a plain file name: not empty, at most 200 bytes")
    assert not (tmp_path / "s.mcap").exists()


@pytest.mark.parametrize("where", ["--values @FILE", "-o KEY=VALUE", "params.yaml",
                                   "index.json", "manifest.json"])
def test_nesting_past_the_limit_is_one_line(tmp_path: Path, where: str,
                                            out_inputs: dict[str, Path]) -> None:
    """Issue 58, 3: `--values @nested.json` with 100,000 nested `[` was a RecursionError. One
    loader (pipeline/json_yaml.py) refuses JSON and YAML nested more than 100 deep."""
    import shutil

    from pipeline.artifact import MANIFEST_HASH_KEY, canonical_manifest_hash

    deep = "[" * 100_000 + "]" * 100_000
    seq, out = out_inputs["seq"], tmp_path / "t.parquet"
    if where == "--values @FILE":
        (tmp_path / "nested.json").write_text(deep)
        args = ["run", "-a", "ndt", "--values", f"@{tmp_path / 'nested.json'}", seq]
    elif where == "-o KEY=VALUE":
        args = ["run", "-a", "ndt", "-o", f"x={deep}", seq]
    elif where == "params.yaml":
        (tmp_path / "p.yaml").write_text("trials: {space: " + "[" * 150 + "]" * 150 + "}\n")
        args = ["run", "-a", "ndt", "--params", tmp_path / "p.yaml", seq]
    elif where == "index.json":
        (tmp_path / "index.json").write_text(deep)
        args = ["trials", "--sequences", tmp_path, "-a", "ndt"]
    else:
        model = tmp_path / "model"
        shutil.copytree(out_inputs["model"], model)
        manifest = json.loads((model / "manifest.json").read_text())
        manifest["training"]["note"] = json.loads("[" * 101 + "]" * 101)
        manifest[MANIFEST_HASH_KEY] = canonical_manifest_hash(manifest)
        (model / "manifest.json").write_text(json.dumps(manifest))
        args = ["select", model, seq]
    fails([*args, "--out", out], "nested more than 100 deep (MAX_NESTING)")
    assert not out.exists()


# ------------------------------------------------------ Issue 58: bounds, silent accepts


@pytest.mark.timeout(120, method="signal")
@pytest.mark.parametrize("value", ["true", "false", "3.0", "0", "1000001",
                                   "1000000000000000000000"])
def test_an_iteration_count_is_an_integer_in_range(tmp_path: Path, value: str) -> None:
    """Issue 58, 2 and 4: `trials.iterations: true` was taken as 1 by `params` and `trials`; a
    22-digit count passed the check and grew memory to 7.6 GiB without starting a trial.
    Integers in [1, 1000000], checked before any work (the test's time limit catches a
    hang)."""
    params = tmp_path / "p.yaml"
    params.write_text(f"trials:\n  iterations: {value}\n")
    rule = "must be an integer in [1, 1000000] (MAX_ITERATIONS)"
    fails(["params", "ndt", "--params", params], "trials.iterations", rule, f"got {value}"
          if value not in ("true", "false") else f"got {value.title()}")
    fails(["trials", "x.mcap", "--out", tmp_path / "o", "--params", params],
          "trials.iterations", rule)
    if value.isdigit():
        fails(["trials", "x.mcap", "--out", tmp_path / "o", "--iterations", value],
              "trials.iterations", rule)
    params.write_text(f"fixed:\n  iterations: {value}\n")
    fails(["trials", "x.mcap", "--joint", "--out", tmp_path / "o", "--params", params],
          "fixed.iterations", rule)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("sql", ["", "   ;  ", " -- a comment", "/* */ ;"])
def test_sql_without_a_statement_is_refused(tmp_path: Path, sql: str,
                                            out_inputs: dict[str, Path]) -> None:
    """Issue 58, 2: `query --db DB ""` and `"   ;  "` exited 0 and printed nothing (empty
    stdin was refused already)."""
    fails(["query", "--db", out_inputs["db"], sql], "holds no statement", repr(sql))
    fails(["query", "--db", out_inputs["db"], sql, "--out", tmp_path / "r.csv"],
          "holds no statement")
    assert not (tmp_path / "r.csv").exists()


def test_rte_refuses_a_study_folder_without_trials(tmp_path: Path) -> None:
    """Issue 58, 2: `rte --trials EMPTY_FOLDER --db good.duckdb` exited 0 and replaced a good
    database of 8 trials with one of 2 (the per-sequence trials dropped without a word)."""
    from helpers.evaluation_data import gt_path, write_sequence, write_study

    seqs = tmp_path / "seqs"
    gt = gt_path(40, step_m=1.0, stop=None)
    stamps = write_sequence(seqs / "s.mcap", gt)
    write_study(tmp_path / "trials", "gicp", {"s": (stamps, gt)}, 4, ["kf_m"])
    write_study(tmp_path / "fixed", "gicp", {"s": (stamps, gt)}, 2, ["kf_m"], joint=True)
    db = tmp_path / "good.duckdb"
    rte = ["rte", "--sequences", seqs, "--fixed", tmp_path / "fixed", "--db", db]
    done = invoke([*rte, "--trials", tmp_path / "trials"])
    assert done.exit_code == 0, (done.output, done.exception)
    before = db.read_bytes()
    (tmp_path / "empty").mkdir()
    fails([*rte, "--trials", tmp_path / "empty"], f"{tmp_path / 'empty'}: no trials in this "
          "trials folder", "leave --trials out")
    assert db.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "fixed", "good.duckdb",
                                                           "seqs", "trials"]


def test_a_model_whose_algorithm_does_not_tune_its_space_is_refused(
        tmp_path: Path, out_inputs: dict[str, Path]) -> None:
    """Issue 58, 2: a manifest's `algorithm` changed from ndt to gicp and re-hashed: `select`
    wrote a schedule labelled gicp with NDT's parameters. The loader checks the manifest's
    space against what its algorithm tunes (select, live and adaptive hand it the adapter's)."""
    import shutil

    from pipeline.artifact import MANIFEST_HASH_KEY, canonical_manifest_hash

    model = tmp_path / "model"
    shutil.copytree(out_inputs["model"], model)
    manifest = json.loads((model / "manifest.json").read_text())
    manifest["algorithm"] = "gicp"
    manifest[MANIFEST_HASH_KEY] = canonical_manifest_hash(manifest)
    (model / "manifest.json").write_text(json.dumps(manifest))
    for command in ("select", "live"):
        fails([command, model, out_inputs["seq"], "--out", tmp_path / "out"],
              "inconsistent artifact", "algorithm 'gicp' tunes [max_correspondence_distance "
              "(float)", "the parameter_space names [resolution (float), keyframe_interval "
              "(float)]")
    assert not (tmp_path / "out").exists()


def test_metric_refuses_renumbered_frames_as_export_does(tmp_path: Path) -> None:
    """Issue 58, 2: `metric rte` scored a trajectory numbered 100..111 (the sequence's stamps)
    against a 12-frame sequence; `export` refused it. One check for both
    (pipeline.trajectory.check_frames_of), every frame, either side of the metric."""
    seq = straight_sequence(tmp_path / "s.mcap")
    stamps = 100_000_000 * np.arange(12, dtype=np.int64)
    T = np.tile(np.eye(4), (12, 1, 1))
    T[:, 0, 3] = np.arange(12)
    traj = tmp_path / "t.parquet"
    write_trajectory(traj, Trajectory(np.arange(100, 112, dtype=np.int32), stamps, T),
                     {"sequence": str(seq)})
    needle = f"{seq}: the trajectory {traj}'s frame 100 (stamp 0 ns) is not a frame of this " \
             "sequence (12 frames"
    fails(["export", traj, "--format", "kitti", "--out", tmp_path / "o.txt"], needle)
    fails(["metric", "rte", seq, traj, "--length", "2"], needle)
    fails(["metric", "rte", traj, seq, "--length", "2"], needle)
    later = np.arange(12, dtype=np.int32)
    later[5] = 50  # the first frame matches: export checked only that one
    write_trajectory(traj, Trajectory(later, stamps, T), {"sequence": str(seq)})
    fails(["export", traj, "--format", "kitti", "--out", tmp_path / "o.txt"], "frame 50")
    fails(["metric", "rte", seq, traj, "--length", "2"], "frame 50")
    assert not (tmp_path / "o.txt").exists()


def corrupt_chunk_of(path: Path, topic: str) -> None:
    """Flip the CRC of the (first) chunk that holds ``topic``'s messages."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    ids = {cid for cid, ch in summary.channels.items() if ch.topic == topic}
    start = next(ci.chunk_start_offset for ci in summary.chunk_indexes
                 if ids & set(ci.message_index_offsets))
    data = bytearray(path.read_bytes())
    assert data[start] == 0x06  # a Chunk record: opcode, length, start, end, size, crc
    data[start + 33] ^= 0xFF
    path.write_bytes(bytes(data))


def test_which_commands_check_which_chunks(tmp_path: Path) -> None:
    """Issue 58, 2: a CRC error in a chunk a command does not read passed `export
    --ground-truth` and `metric rte`, while design.md said every chunk is checked. Checking
    every chunk costs those commands 10-24x their time (bench/bench_crc.py; the rule was 10 %),
    so the documented behaviour is pinned here: they check the ground truth's chunks, not the
    scans'; `info` checks every chunk, those of other channels (TF) included, which it did
    not."""
    scans_bad = straight_sequence(tmp_path / "a.mcap")
    corrupt_chunk_of(scans_bad, "/lidar/points")
    out = tmp_path / "gt.txt"
    for args in (["export", scans_bad, "--ground-truth", "--format", "kitti", "--out", out],
                 ["metric", "rte", scans_bad, scans_bad, "--length", "2"]):
        done = invoke(args)
        assert done.exit_code == 0, done.output  # documented: the scans' chunks are not read
    fails(["info", scans_bad], "crc validation failed")
    gt_bad = straight_sequence(tmp_path / "b.mcap")
    corrupt_chunk_of(gt_bad, "/ground_truth/pose")
    fails(["export", gt_bad, "--ground-truth", "--format", "kitti", "--out", tmp_path / "x"],
          "crc validation failed")
    fails(["metric", "rte", gt_bad, gt_bad, "--length", "2"], "crc validation failed")
    fails(["info", gt_bad], "crc validation failed")
    tf_bad = tmp_path / "c.mcap"
    with SequenceWriter(tf_bad, SequenceInfo(name="c")) as w:  # no ground truth: scans and TF
        for k in range(3):
            w.add(10 + k, np.full((5, 3), k, np.float32))
            w.add_tf(10 + k, "map", "lidar", np.eye(4))
    corrupt_chunk_of(tf_bad, "/tf")
    fails(["info", tf_bad], "crc validation failed")
