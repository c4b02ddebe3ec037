"""Writes are atomic (issue 13, item 1; issue 18, item 5): on any error the previous output stays
byte-identical and no temporary remains; a killed writer's temporary is removed by the next
write; outputs get the umask's permissions; bad output paths are one line, exit 1."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.errors import InputError, OutputError
from pipeline.io_utils import atomic_dir, atomic_path, atomic_write_text
from pipeline.sequence import SequenceInfo, SequenceReader, SequenceWriter
from stages.cli import main

REPO = Path(__file__).resolve().parents[1]


def leftovers(folder: Path, name: str) -> list[Path]:
    return sorted(folder.glob(f".{name}.*"))


def write_sequence(path: Path, frames: int = 2) -> None:
    with SequenceWriter(path, SequenceInfo(name="s")) as w:
        for k in range(frames):
            w.add(10 + k, np.ones((5, 3), np.float32) * k)


@pytest.fixture
def umask_022() -> Iterator[None]:
    old = os.umask(0o022)
    yield
    os.umask(old)


def empty_pointcloud_mcap(path: Path) -> None:
    """An MCAP with a PointCloud2 channel and no messages (the issue's reproduction)."""
    from mcap.writer import Writer

    from pipeline.ros2_cdr import POINTCLOUD2, schema_text

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(POINTCLOUD2, "ros2msg", schema_text(POINTCLOUD2).encode())
        w.register_channel("/points", "cdr", sid)
        w.finish()


def test_failed_finish_keeps_the_previous_output(tmp_path: Path) -> None:
    """`ingest mcap X --out good.mcap` with no frames in X: exit 1 and good.mcap unchanged
    (SequenceWriter.__exit__ used to report success to the atomic write when _finish raised)."""
    good = tmp_path / "good.mcap"
    write_sequence(good)
    before = good.read_bytes()
    empty = tmp_path / "x.mcap"
    empty_pointcloud_mcap(empty)
    result = CliRunner().invoke(main, ["ingest", "mcap", str(empty), "--out", str(good)])
    assert result.exit_code == 1 and "no frames to write" in result.stderr, result.output
    assert good.read_bytes() == before
    assert leftovers(tmp_path, "good.mcap") == []
    with pytest.raises(InputError, match="no frames"), SequenceWriter(good, SequenceInfo("e")):
        pass
    assert good.read_bytes() == before and leftovers(tmp_path, "good.mcap") == []


def test_error_in_the_block_keeps_the_previous_output(tmp_path: Path) -> None:
    out = tmp_path / "a.txt"
    atomic_write_text(out, "old")
    with pytest.raises(RuntimeError), atomic_path(out) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert out.read_text() == "old" and leftovers(tmp_path, "a.txt") == []
    folder = tmp_path / "model"
    with atomic_dir(folder) as tmp:
        (tmp / "f").write_text("v1")
    with pytest.raises(RuntimeError), atomic_dir(folder) as tmp:
        (tmp / "f").write_text("v2")
        raise RuntimeError("boom")
    assert (folder / "f").read_text() == "v1" and leftovers(tmp_path, "model") == []


def test_a_killed_writers_temporary_is_removed_by_the_next_write(tmp_path: Path) -> None:
    """SIGKILL during a write leaves `.<name>.<pid>.<hex>.tmp`; the next write of the same
    output removes it (a live writer's temporary is kept)."""
    out = tmp_path / "big.mcap"
    script = textwrap.dedent(f"""
        import sys, time
        from pipeline.io_utils import atomic_path
        with atomic_path({str(out)!r}) as tmp:
            tmp.write_bytes(b"x" * 1_000_000)
            print("writing", flush=True)
            time.sleep(60)
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                             cwd=REPO)
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "writing"
        live = leftovers(tmp_path, "big.mcap")
        assert len(live) == 1 and f".{child.pid}." in live[0].name
        write_sequence(tmp_path / "other.mcap")  # another output: not touched
        assert leftovers(tmp_path, "big.mcap") == live
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    assert leftovers(tmp_path, "big.mcap") == live and not out.exists()
    legacy = tmp_path / ".big.mcap.k2j4_x9q.tmp"  # mkstemp's name (earlier versions)
    legacy.write_bytes(b"old")
    write_sequence(out)
    assert leftovers(tmp_path, "big.mcap") == []
    with SequenceReader(out) as r:
        assert len(r) == 2


def test_outputs_follow_the_umask(tmp_path: Path, umask_022: None) -> None:
    """Files 0644 and folders 0755 under umask 022 (mkstemp made them 0600 / 0700)."""
    write_sequence(tmp_path / "s.mcap")
    atomic_write_text(tmp_path / "a.txt", "x")
    with atomic_dir(tmp_path / "d") as tmp:
        (tmp / "f").write_text("x")
    assert (tmp_path / "s.mcap").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "d").stat().st_mode & 0o777 == 0o755
    os.umask(0o077)
    atomic_write_text(tmp_path / "b.txt", "x")
    assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o600


def test_output_paths_that_cannot_be_written(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    cases = {
        "": "the output path is empty",
        str(tmp_path): "is a folder",
        str(tmp_path / "file" / "s.txt"): f"{tmp_path / 'file'} is a file",
        "/sys/adaptune-test.txt": "cannot write (Permission denied)",
    }
    for path, message in cases.items():
        with pytest.raises(OutputError, match=message.replace("(", r"\(").replace(")", r"\)")):
            atomic_write_text(path, "x")
    with pytest.raises(OutputError, match="is a file; the output must be a folder"):
        atomic_dir(tmp_path / "file").__enter__()


@pytest.mark.parametrize("out, message", [
    ("", "is a folder"),  # click turns an empty --out into "."
    ("{tmp}/file/s.mcap", "is a file"),
    ("/sys/adaptune-test.mcap", "Permission denied"),
])
def test_bad_out_is_one_line(tmp_path: Path, out: str, message: str) -> None:
    (tmp_path / "file").write_text("x")
    seq = tmp_path / "s.mcap"
    write_sequence(seq)
    result = CliRunner().invoke(main, ["ingest", "mcap", str(seq), "--out",
                                       out.format(tmp=tmp_path)])
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error: ") and message in lines[0]


def test_out_equal_to_an_input_is_refused(tmp_path: Path) -> None:
    """`ingest mcap X --out X` used to rewrite X (and drop its ground truth)."""
    seq = tmp_path / "s.mcap"
    write_sequence(seq)
    before = seq.read_bytes()
    for out in (seq, tmp_path / "." / "s.mcap"):
        result = CliRunner().invoke(main, ["ingest", "mcap", str(seq), "--out", str(out)])
        assert result.exit_code == 1 and "the output is also an input" in result.stderr
    assert seq.read_bytes() == before


@pytest.mark.parametrize("args, victim", [
    (["run", "-a", "ndt", "{seq}", "--out", "{seq}"], "seq"),
    (["run", "-a", "ndt", "--params", "@{params}", "{seq}", "--out", "{params}"], "params"),
    (["export", "{seq}", "--ground-truth", "--format", "tum", "--out", "{seq}"], "seq"),
    (["export", "{traj}", "--format", "kitti", "--out", "{traj}"], "traj"),
    (["export", "{traj}", "--format", "kitti", "--sequence", "{seq}", "--out", "{seq}"], "seq"),
    (["select", "{model}", "{seq}", "--out", "{seq}"], "seq"),
    (["select", "{model}", "{seq}", "--out", "{model}/manifest.json"], "manifest"),
    (["live", "{model}", "{seq}", "--out", "{seq}"], "seq"),
])
def test_no_command_writes_over_its_input(tmp_path: Path, args: list[str], victim: str) -> None:
    """`run SEQ --out SEQ` replaced the sequence with a trajectory and exited 0 (found auditing
    issue 13, item 1): every command that reads and writes refuses, and the input stays."""
    from pipeline.trajectory import Trajectory, write_trajectory

    paths = {"seq": tmp_path / "s.mcap", "params": tmp_path / "p.json",
             "traj": tmp_path / "t.parquet", "model": tmp_path / "model",
             "manifest": tmp_path / "model" / "manifest.json"}
    write_sequence(paths["seq"])
    paths["params"].write_text('{"resolution": 2.0}')
    write_trajectory(paths["traj"], Trajectory(np.arange(2), np.array([10, 11]),
                                               np.tile(np.eye(4), (2, 1, 1))),
                     {"sequence": str(paths["seq"])})
    paths["model"].mkdir()
    paths["manifest"].write_text("{}")
    before = paths[victim].read_bytes()
    result = CliRunner().invoke(main, [a.format(**paths) for a in args])
    assert result.exit_code == 1, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "the output is also an input" in lines[0], result.stderr
    assert paths[victim].read_bytes() == before


FOLDER_COMMANDS = {
    "ingest-set": ["ingest-set", "--out", "{out}"],
    "simulate-set": ["simulate-set", "--out", "{out}"],
    "simulate-kitti-set": ["simulate-kitti-set", "--out", "{out}"],
    "trials": ["trials", "{seq}", "-a", "ndt", "--iterations", "1", "--length-m", "0.5",
               "--out", "{out}"],
    "run -a command (its work folder)": [
        "run", "-a", "command", "-o", 'command=["true"]', "-o",
        'space=[{{"name": "x", "low": 0, "high": 1, "default": 0.5}}]', "-o", "workdir={out}",
        "{seq}", "--out", "{tmp}/t.parquet"],
}


@pytest.mark.parametrize("where", ["under a file", "read-only"])
@pytest.mark.parametrize("command", sorted(FOLDER_COMMANDS))
def test_an_output_folder_that_cannot_be_made_is_one_line(
        tmp_path: Path, command: str, where: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 32, case 7: `--out` under a file, or where no folder can be made (/sys), was a
    NotADirectoryError / PermissionError traceback in the data-set stages and trials: one
    folder creator (pipeline.io_utils.output_folder) now names the file in the way or the
    reason, before any work is done."""
    (tmp_path / "file").write_text("x")
    seq = tmp_path / "s.mcap"
    with SequenceWriter(seq, SequenceInfo(name="s")) as w:  # 3 frames, 1 m apart
        for k in range(3):
            T = np.eye(4)
            T[0, 3] = k
            w.add(10 + k, np.ones((5, 3), np.float32) * k, T)
    out = tmp_path / "file" / "x" if where == "under a file" else Path("/sys/adaptune-x")
    args = [a.format(out=out, seq=seq, tmp=tmp_path) for a in FOLDER_COMMANDS[command]]
    monkeypatch.chdir(tmp_path)  # no ./params.yaml: every section at its defaults
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, (result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("adaptune: error: "), result.stderr
    reason = f"{tmp_path / 'file'} is a file" if where == "under a file" else "not permitted"
    assert reason in lines[0], lines[0]


def sequence_with_ground_truth(path: Path, frames: int = 6) -> Path:
    """``frames`` scans of 5 points, the ground truth 1 m apart along x."""
    with SequenceWriter(path, SequenceInfo(name="s")) as w:
        for k in range(frames):
            T = np.eye(4)
            T[0, 3] = k
            w.add(10 + k, np.ones((5, 3), np.float32) * k, T)
    return path


STDOUT_COMMANDS = {
    "info --json": ["info", "--json", "{seq}"],
    "query": ["query", "--db", "{db}", "SELECT * FROM t"],
    "metric rte --json": ["metric", "rte", "{seq}", "{seq}", "--length", "2", "--json"],
    "params --json": ["params", "ndt", "--json"],
}


@pytest.mark.parametrize("device", ["full", "closed pipe"])
@pytest.mark.parametrize("command", sorted(STDOUT_COMMANDS))
def test_a_stdout_that_takes_nothing_is_one_line(tmp_path: Path, command: str,
                                                 device: str) -> None:
    """Issue 32, case 7: stdout on a full device (/dev/full: ENOSPC) or a pipe whose reader has
    gone (EPIPE) was an OSError traceback; the one stdout writer (stages.common.write_output)
    makes it one line and exit 1."""
    import duckdb

    seq = sequence_with_ground_truth(tmp_path / "s.mcap")
    db = tmp_path / "r.duckdb"
    with duckdb.connect(str(db)) as con:
        con.execute("CREATE TABLE t AS SELECT range AS x FROM range(10)")
    args = [a.format(seq=seq, db=db) for a in STDOUT_COMMANDS[command]]
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        with open("/dev/full", "wb") as full:
            out = full.fileno() if device == "full" else write_end
            done = subprocess.run([sys.executable, "-m", "stages.cli", *args], stdout=out,
                                  stderr=subprocess.PIPE, cwd=tmp_path, timeout=120,
                                  env={**os.environ, "PYTHONPATH": str(REPO)})
    finally:
        os.close(write_end)
    lines = done.stderr.decode().strip().splitlines()
    reason = "No space left on device" if device == "full" else "Broken pipe"
    assert done.returncode == 1 and len(lines) == 1, done.stderr.decode()
    assert lines[0] == f"adaptune: error: stdout: cannot write the output ({reason})", lines


def test_metrics_hold_the_figures_and_the_record_the_rest(tmp_path: Path) -> None:
    """write_metrics splits a summary: text, the named bookkeeping keys (wherever they nest)
    and lists of text go to the record, figures (numbers, null, lists of numbers) to the
    metrics; read_summary puts back exactly the summary."""
    import json

    from pipeline.outputs import read_summary, record_beside, split_leaves, write_metrics

    summary = {"algorithm": "ndt", "length_m": 25.0, "rte_pct": {"baseline": 2.0, "fixed": None},
               "splits": {"validation": {"sequences": ["a", "b"], "ratio": 0.5,
                                         "kitti": {"segments": 7, "t_err_pct": 1.5}}},
               "per_world": {"w": {"wall_time_s": 3.0, "name": "w"}},
               "summary": {"median_interval": [0.9, 1.1]}}
    figures, record = split_leaves(summary, ("length_m", "segments", "wall_time_s"))
    assert figures == {"rte_pct": {"baseline": 2.0, "fixed": None},
                       "splits": {"validation": {"ratio": 0.5, "kitti": {"t_err_pct": 1.5}}},
                       "summary": {"median_interval": [0.9, 1.1]}}
    assert record == {"algorithm": "ndt", "length_m": 25.0,
                      "splits": {"validation": {"sequences": ["a", "b"],
                                                "kitti": {"segments": 7}}},
                      "per_world": {"w": {"wall_time_s": 3.0, "name": "w"}}}
    metrics = tmp_path / "metrics" / "x.json"
    write_metrics(metrics, record_beside(metrics), summary, ("length_m", "segments",
                                                             "wall_time_s"))
    assert json.loads(metrics.read_text()) == figures
    assert (tmp_path / "records" / "x.json").is_file()
    back = read_summary(metrics)
    assert json.dumps(back, sort_keys=True) == json.dumps(summary, sort_keys=True)
    with pytest.raises(InputError, match=r"missing\.json"):
        read_summary(tmp_path / "metrics" / "missing.json")
