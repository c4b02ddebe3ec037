"""The documented example of an external odometry (issue 34, item 2): KISS-ICP's own command
line, ``kiss_icp_pipeline``, tuned through the ``command`` adapter by examples/kiss_icp/ (a
wrapper of the standard library only, the scans handed over as KITTI .bin files), on a small
simulated sequence; and the snippet of docs/usage.md that reads a schedule as a ROS node would.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "kiss_icp"
BIN = Path(sys.executable).parent
FRAMES = 24


def adaptune(*args: object) -> str:
    """``adaptune ARGS`` in the repository (where the example's paths are relative to)."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run([str(BIN / "adaptune"), *map(str, args)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("kiss") / "street.mcap"
    adaptune("simulate", "--world", "street", "--sensor", "vlp16", "--frames", FRAMES,
             "--seed", 4, "--out", path)
    return path


def test_the_tool_imports_nothing_of_adaptune() -> None:
    tree = ast.parse((EXAMPLE / "kiss_icp_tool.py").read_text())
    modules = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import)
               for a in n.names}
    modules |= {n.module.split(".")[0] for n in ast.walk(tree)
                if isinstance(n, ast.ImportFrom) and n.module}
    assert modules <= set(sys.stdlib_module_names) | {"__future__"}, modules


def test_kiss_icp_pipeline_is_tuned_through_the_command_adapter(sequence: Path,
                                                                tmp_path: Path) -> None:
    """The example's params with a budget of two trials: a study of kiss_icp_pipeline runs, and
    a run at KISS-ICP's defaults gives the trajectory adaptune's in-process kiss_icp adapter
    gives (the same library behind the command line)."""
    from pipeline.tuning.layout import read_trials_tables

    params = yaml.safe_load((EXAMPLE / "params.yaml").read_text())
    params["trials"].update(iterations=2, startup_trials=2, workers=1)
    params["base"] = {"length_m": 5.0}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    out = json.loads(adaptune("trials", "--params", tmp_path / "params.yaml", sequence,
                              "--out", tmp_path / "trials", "--json"))
    assert out[0]["trials"] == 2 and out[0]["failed"] == 0, out
    table = read_trials_tables(tmp_path / "trials").to_pylist()
    assert [r["status"] for r in table] == ["ok", "ok"]
    adaptune("run", "--params", tmp_path / "params.yaml", sequence, "--out",
             tmp_path / "cli.parquet")
    # the tool gets KITTI .bin files, without the swept scans' per-point times, and does not
    # deskew; the in-process adapter deskews by default
    adaptune("run", "--params", tmp_path / "params.yaml", "-a", "kiss_icp", "-o",
             "deskew=false", sequence, "--out", tmp_path / "inproc.parquet")
    from pipeline.metrics.rte import mean_rte_pct
    from pipeline.sequence import SequenceReader
    from pipeline.trajectory import read_trajectory

    cli = read_trajectory(tmp_path / "cli.parquet").T_world_lidar
    inproc = read_trajectory(tmp_path / "inproc.parquet").T_world_lidar
    np.testing.assert_allclose(cli, inproc, atol=1e-4)
    with SequenceReader(sequence) as reader:  # trial 0 ran KISS-ICP's defaults: that RTE
        gt = reader.require_ground_truth("to score")
    baseline = next(r for r in table if r["trial"] == 0)
    assert baseline["objective"] == pytest.approx(mean_rte_pct(gt, inproc, 5.0), rel=1e-3)


SNIPPET_START = "<!-- schedule snippet -->"


def test_the_documented_schedule_reader(tmp_path: Path) -> None:
    """docs/usage.md's snippet reads a schedule (CSV, as `adaptune select --out X.csv` writes
    it) and gives each scan the row in force at its stamp."""
    from pipeline.odometry.base import Schedule

    text = (REPO / "docs" / "usage.md").read_text()
    code = text.split(SNIPPET_START, 1)[1].split("```python", 1)[1].split("```", 1)[0]
    schedule = Schedule(np.arange(4, dtype=np.int32),
                        {"voxel_size": np.array([1.0, 1.0, 0.5, 0.5]),
                         "max_range": np.array([100.0, 80.0, 80.0, 60.0])},
                        np.array([10**9, 11 * 10**8, 12 * 10**8, 13 * 10**8], np.int64))
    schedule.write(tmp_path / "schedule.csv")
    scope: dict = {}
    cwd = Path.cwd()
    os.chdir(tmp_path)
    try:
        exec(compile(code, "usage.md", "exec"), scope)  # the documented snippet, as written
    finally:
        os.chdir(cwd)
    params_at = scope["params_at"]
    assert params_at(11 * 10**8 + 5) == {"voxel_size": 1.0, "max_range": 80.0}
    assert params_at(12 * 10**8) == {"voxel_size": 0.5, "max_range": 80.0}
    assert params_at(5 * 10**8) == {"voxel_size": 1.0, "max_range": 100.0}  # before: the first
    assert params_at(10**10) == {"voxel_size": 0.5, "max_range": 60.0}
