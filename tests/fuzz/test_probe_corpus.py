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
    """Case 3: `ingest: {train: ["../../kr/sequences/04"]}` wrote next to the KITTI root and
    index.json recorded the `..` path; `ingest --name` and `simulate --name` took `..` and `/`.
    One path guard (pipeline.io_utils.check_plain_name) for every name that becomes a file."""
    from test_fuzz_cli import kitti_layout

    kitti_layout(tmp_path / "kr")
    before = files_under(tmp_path)
    params = tmp_path / "p.yaml"
    params.write_text(f'ingest: {{kitti_root: "{tmp_path / "kr"}", '
                      'train: ["../../kr/sequences/00"]}\n')
    out = tmp_path / "a" / "b" / "out"
    fails(["ingest-set", "--params", params, "--out", out], "train entry",
          "plain file name", "../../kr/sequences/00")
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
    it."""
    params = tmp_path / "p.yaml"
    params.write_text('ingest: {kitti_root: null, train: ["04"]}\n')
    fails(["ingest-set", "--params", params, "--out", tmp_path / "out"], "kitti_root",
          "no file would be behind the index")
    assert not (tmp_path / "out" / "index.json").exists()
