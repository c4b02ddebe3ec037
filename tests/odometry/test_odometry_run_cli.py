"""``adaptune run`` through the CLI: fixed params, a schedule, and bad input (exit 1, no output)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.odometry_data import Seq

from pipeline.errors import InputError
from pipeline.odometry import get_adapter
from pipeline.odometry.base import Schedule
from pipeline.trajectory import read_trajectory
from stages.cli import main


def test_run_with_params_and_options(synthetic_seq: Seq, tmp_path: Path) -> None:
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "--params", '{"resolution": 3.0}',
                                    "-o", "source_voxel_m=0.8", str(synthetic_seq.path),
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    traj = read_trajectory(out)
    assert len(traj) == len(synthetic_seq) and traj.is_finite()
    odom = get_adapter("ndt", source_voxel_m=0.8).start({"resolution": 3.0})
    direct = np.stack([odom.step(s.xyz, s.stamp_ns) for s in synthetic_seq.scans])
    np.testing.assert_array_equal(traj.T_world_lidar[:, :3], direct[:, :3])


def test_run_summary_on_stderr_or_json_on_stdout(synthetic_seq: Seq, tmp_path: Path) -> None:
    out = tmp_path / "t.parquet"
    args = ["run", "-a", "ndt", str(synthetic_seq.path), "--out", str(out)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0 and res.stdout == ""
    assert res.stderr == f"ndt: {len(synthetic_seq)} poses -> {out}\n"
    res = CliRunner().invoke(main, [*args, "--json"])
    assert res.exit_code == 0 and res.stderr == ""
    assert json.loads(res.stdout) == {"algorithm": "ndt", "sequence": str(synthetic_seq.path),
                                      "poses": len(synthetic_seq), "out": str(out)}


def test_run_with_schedule_file(synthetic_seq: Seq, tmp_path: Path) -> None:
    n = len(synthetic_seq)
    sched = Schedule.constant(get_adapter("ndt").space.defaults(), n)
    sched.values["keyframe_interval"][n // 2:] = 1.0
    sched.write(tmp_path / "s.parquet")
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"resolution": 4.0}))
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "--schedule", str(tmp_path / "s.parquet"),
                                    str(synthetic_seq.path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert len(read_trajectory(out)) == n
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "--params", f"@{params}",
                                    str(synthetic_seq.path), "--out", str(tmp_path / "u.parquet")])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize(("args", "message"), [
    (["-a", "loam"], "unknown odometry algorithm 'loam'"),
    (["-a", "ndt", "--params", "{resolution: 3"], "--params: not valid JSON"),
    (["-a", "ndt", "--params", "[1, 2]"], "--params: must be a JSON object"),
    (["-a", "ndt", "--params", '{"bogus": 1}'], "unknown parameter 'bogus'"),
    (["-a", "ndt", "--params", '{"resolution": 50}'], "resolution must be in [1.0, 10.0], got 50"),
    (["-a", "ndt", "-o", "neighbors=3"], "neighbors must be 1 or 7"),
    (["-a", "ndt", "-o", "novalue"], "--option must be key=value"),
    (["-a", "gicp", "--params", "@/nonexistent/p.json"], "no such parameters file"),
    # values that are not numbers (issue 13, items 7 and 8)
    (["-a", "ndt", "--params", '{"resolution": "abc"}'],
     'resolution must be a number, got "abc" (str)'),
    (["-a", "ndt", "--params", '{"resolution": "4.0"}'],
     'resolution must be a number, got "4.0" (str)'),
    (["-a", "ndt", "--params", '{"resolution": [4]}'], "resolution must be a number, got [4]"),
    (["-a", "ndt", "--params", '{"resolution": null}'],
     "resolution must be a number, got null (NoneType)"),
    (["-a", "ndt", "--params", '{"resolution": true}'],
     "resolution must be a number, got true (bool)"),
    (["-a", "ndt", "--time-limit", "nan"], "time limit must be a number of seconds > 0, got nan"),
])
def test_bad_input_fails_with_one_line(args: list[str], message: str, synthetic_seq: Seq,
                                       tmp_path: Path) -> None:
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", *args, str(synthetic_seq.path), "--out", str(out)])
    assert res.exit_code == 1, res.output
    assert "adaptune: error: " in res.output and message in res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_missing_sequence_and_short_schedule(tmp_path: Path, synthetic_seq: Seq) -> None:
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", "-a", "ndt", str(tmp_path / "nope.mcap"),
                                    "--out", str(out)])
    assert res.exit_code == 1 and "nope.mcap: no such sequence file" in res.output
    Schedule.constant(get_adapter("ndt").space.defaults(), 3).write(tmp_path / "s.parquet")
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "--schedule", str(tmp_path / "s.parquet"),
                                    str(synthetic_seq.path), "--out", str(out)])
    assert res.exit_code == 1 and "covers 3 frames, the sequence has 20" in res.output
    assert not out.exists()


@pytest.mark.parametrize("dropped", ["frame", "stamp_ns"])
def test_a_schedule_without_frame_or_stamp_fails_with_one_line(
        dropped: str, synthetic_seq: Seq, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    path = tmp_path / "s.parquet"
    Schedule.constant(get_adapter("ndt").space.defaults(), len(synthetic_seq)).write(path)
    table = pq.read_table(path)
    pq.write_table(table.drop_columns([dropped]), path)  # the schema version stays
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "--schedule", str(path),
                                    str(synthetic_seq.path), "--out", str(out)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert res.output.strip() == (f"adaptune: error: {path}: a schedule needs the columns frame "
                                  f"and stamp_ns, {dropped} missing")
    assert not out.exists()


@pytest.mark.parametrize(("column", "values", "shown"), [
    ("frame", [0.0, 1.5], "1.5"),                   # a fraction of a frame
    ("frame", [0.0, 2.0**31], "2147483648.0"),      # beyond int32: it wrapped to -2**31
    ("frame", [0.0, float("nan")], "nan"),
    ("stamp_ns", [0.0, 1e30], "1e+30"),             # beyond int64
])
def test_a_schedule_column_of_non_whole_numbers_fails_with_one_line(
        column: str, values: list[float], shown: str, tmp_path: Path) -> None:
    """The fuzz suite's frame of 2**31 in a float column: cast with a numpy warning to a wrong
    frame before; now refused naming the column, its range and the value."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "s.parquet"
    Schedule.constant(get_adapter("ndt").space.defaults(), 2).write(path)
    table = pq.read_table(path)
    table = table.set_column(table.column_names.index(column), column,
                             pa.array(values, pa.float64()))
    pq.write_table(table, path)
    kind = "int32" if column == "frame" else "int64"
    info = np.iinfo(kind)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError) as err:
            Schedule.read(path)
    assert str(err.value) == (f"{path}: schedule column {column} must hold whole numbers in "
                              f"[{info.min}, {info.max}], got {shown}")


def test_a_command_writing_a_non_utf8_trajectory_fails_with_one_line(
        synthetic_seq: Seq, tmp_path: Path) -> None:
    write = "import sys; open(sys.argv[1], 'wb').write(bytes([0xff, 0xfe, 0x31, 0x0a]))"
    space = [{"name": "k", "low": 0.0, "high": 1.0, "default": 0.5}]
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, [
        "run", "-a", "command", "-o", f"command={json.dumps(['{python}', '-c', write, '{out}'])}",
        "-o", f"space={json.dumps(space)}", str(synthetic_seq.path), "--out", str(out)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert res.output.strip() == ("adaptune: error: command: trajectory.txt is not UTF-8 text "
                                  "(byte 0xff at offset 0)")


def test_run_takes_a_params_file_as_every_stage_does(synthetic_seq: Seq, tmp_path: Path,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    """--params is a params.yaml: its trials.algorithm, adapter_options and space (here a
    baseline resolution of 3 m) give the run; --values sets parameters; the frames show
    progress (log lines off a terminal)."""
    import yaml

    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"trials": {
        "algorithm": "ndt", "adapter_options": {"source_voxel_m": 0.8},
        "space": {"resolution": {"default": 3.0}}}}))
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(main, ["run", "--params", str(params), str(synthetic_seq.path),
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    odom = get_adapter("ndt", source_voxel_m=0.8).start({"resolution": 3.0})
    direct = np.stack([odom.step(s.xyz, s.stamp_ns) for s in synthetic_seq.scans])
    np.testing.assert_array_equal(read_trajectory(out).T_world_lidar[:, :3], direct[:, :3])
    assert f"ndt on yard: {len(synthetic_seq)} frames" in caplog.text
    assert "ndt on yard finished" in caplog.text
    values = tmp_path / "v.parquet"
    res = CliRunner().invoke(main, ["run", "--params", str(params), "--values",
                                    '{"resolution": 3.0}', str(synthetic_seq.path),
                                    "--out", str(values)])
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_trajectory(values).T_world_lidar, direct)
    res = CliRunner().invoke(main, ["run", "--params", str(tmp_path / "none.yaml"),
                                    str(synthetic_seq.path), "--out", str(values)])
    assert res.exit_code == 1 and "none.yaml: no such params file" in res.output


def test_export_finds_the_sequence_from_anywhere(synthetic_seq: Seq, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A run names its sequence relative to its own folder, as trials do: `export` works
    after a `cd`, and the file's bytes do not depend on where the project lies."""
    import shutil

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    shutil.copy(synthetic_seq.path, tmp_path / "a" / "seq.mcap")
    monkeypatch.chdir(tmp_path / "a")
    res = CliRunner().invoke(main, ["run", "-a", "ndt", "seq.mcap", "--out", "traj.parquet"])
    assert res.exit_code == 0, res.output
    import pyarrow.parquet as pq

    meta = pq.read_schema("traj.parquet").metadata
    assert meta[b"adaptune.sequence"] == b"seq.mcap"
    monkeypatch.chdir(tmp_path / "b")
    res = CliRunner().invoke(main, ["export", "../a/traj.parquet", "--format", "tum",
                                    "--out", "traj.tum"])
    assert res.exit_code == 0, res.output
    assert len((tmp_path / "b" / "traj.tum").read_text().splitlines()) == len(synthetic_seq)


def test_a_trial_trajectory_exports_from_anywhere(synthetic_seq: Seq, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A trial's trajectory names its sequence relative to its own folder (it named the
    sequence alone before: `export` then needed --sequence): the project can move and `export`
    runs from any folder (issue 34, item 5)."""
    import shutil

    from pipeline.tuning.layout import trajectory_path

    (tmp_path / "project").mkdir()
    (tmp_path / "elsewhere").mkdir()
    shutil.copy(synthetic_seq.path, tmp_path / "project" / "seq.mcap")
    monkeypatch.chdir(tmp_path / "project")
    res = CliRunner().invoke(main, ["trials", "seq.mcap", "-a", "ndt", "--iterations", "1",
                                    "--length-m", "1", "--out", "trials"])
    assert res.exit_code == 0, res.output
    shutil.move(tmp_path / "project", tmp_path / "moved")
    monkeypatch.chdir(tmp_path / "elsewhere")
    traj = trajectory_path(tmp_path / "moved" / "trials", "ndt", "seq", 0)
    res = CliRunner().invoke(main, ["export", str(traj), "--format", "tum", "--out", "t.tum"])
    assert res.exit_code == 0, res.output
    assert len((tmp_path / "elsewhere" / "t.tum").read_text().splitlines()) == len(synthetic_seq)
