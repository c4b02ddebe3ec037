"""Search ranges overridable in params.yaml (``trials.space``), listed by ``adaptune params``,
and the space a study searched stored with its trials for the later stages."""

from __future__ import annotations

import json
from concurrent.futures import Executor
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from helpers.tuning_settings import settings

from pipeline.errors import ConfigError
from pipeline.odometry import get_adapter
from pipeline.odometry.base import with_space
from pipeline.tuning.smbo import run_trials
from pipeline.tuning.table import read_space, trials_path
from stages.cli import main


def params_file(tmp_path: Path, algorithm: str, space: object) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(json.dumps({"base": {"seed": 1}, "trials": {"algorithm": algorithm,
                                                                 "space": space}}))
    return path


def test_params_lists_the_built_in_and_the_overridden_ranges(tmp_path: Path) -> None:
    res = CliRunner().invoke(main, ["params", "ndt"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines() == [
        "ndt: 2 parameters (built-in ranges)",
        "name               low  high  default  kind   scale   unit",
        "-----------------  ---  ----  -------  -----  ------  ----",
        "resolution         1    10    4        float  linear  m",
        "keyframe_interval  0    10    4        float  linear  m"]
    params = params_file(tmp_path, "ndt", {"resolution": {"low": 0.5, "high": 12, "log": True}})
    res = CliRunner().invoke(main, ["params", "ndt", "--params", str(params), "--json"])
    assert res.exit_code == 0, res.output
    shown = json.loads(res.output)
    assert shown["source"] == f"{params} trials.space"
    assert shown["parameters"][0] == {"name": "resolution", "low": 0.5, "high": 12.0,
                                      "default": 4.0, "kind": "float", "log": True, "unit": "m"}
    assert shown["parameters"][1] == get_adapter("ndt").space.to_json()[1]


@pytest.mark.parametrize("algorithm, space, message", [
    ("ndt", {"bogus": {"low": 1}},
     "trials.space: unknown parameter 'bogus' (known: resolution, keyframe_interval)"),
    ("ndt", {"resolution": {"low": 5, "high": 2}},
     "trials.space.resolution: high must be > low, got (low=5, high=2)"),
    ("ndt", {"resolution": {"default": 20}},
     "trials.space.resolution: default must be in [low, high], got (low=1, high=10, default=20)"),
    ("ndt", {"keyframe_interval": {"log": True}},
     "trials.space.keyframe_interval: log scale needs low > 0, got low=0"),
    ("kiss_icp", {"max_points_per_voxel": {"low": 1.5}},
     "trials.space.max_points_per_voxel: an integer parameter needs integral low, high and "
     "default, got (low=1.5, high=50, default=20)"),
    ("ndt", {"resolution": {"low": "abc"}},
     "trials.space.resolution.low: Input should be a valid number, got 'abc'"),
    ("ndt", {"resolution": {"high": True}},
     "trials.space.resolution.high: Input should be a valid number, got True"),
    ("ndt", {"resolution": {"step": 1}},
     "trials.space.resolution.step: unknown parameter, got 1"),
])
def test_a_bad_range_is_one_line(tmp_path: Path, algorithm: str, space: object,
                                 message: str) -> None:
    params = params_file(tmp_path, algorithm, space)
    res = CliRunner().invoke(main, ["params", algorithm, "--params", str(params)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert res.output.strip().splitlines() == [f"adaptune: error: {message}"]


def test_a_widened_space_is_searched_run_and_stored(sequences: list[Path], pool: Executor,
                                                    tmp_path: Path) -> None:
    """bias in [-2, 2] with default 1.5: outside the drift adapter's built-in [-1, 1]."""
    s = settings(iterations=6, space={"bias": {"low": -2.0, "high": 2.0, "default": 1.5}})
    run_trials(sequences[:1], tmp_path, s, seed=2, progress=False, executor=pool)
    t = pq.read_table(trials_path(tmp_path, "drift", "seq_a")).to_pydict()
    assert t["p_bias"][0] == 1.5 and set(t["status"]) == {"ok"}  # the baseline: new default
    assert all(-2.0 <= b <= 2.0 for b in t["p_bias"]) and any(abs(b) > 1 for b in t["p_bias"])
    space = read_space(tmp_path, "drift")  # the one home of the space for the later stages
    assert (space["bias"].low, space["bias"].high, space["bias"].default) == (-2.0, 2.0, 1.5)
    assert space["gain"] == get_adapter_space_gain()
    # a resume with other ranges is another study
    with pytest.raises(ConfigError, match="parameter space differs"):
        run_trials(sequences[:1], tmp_path, settings(iterations=6), seed=2, progress=False,
                   executor=pool)


def get_adapter_space_gain() -> object:
    from helpers.tuning_adapters import SPACE

    return SPACE["gain"]


def test_built_in_adapters_accept_values_of_a_widened_space() -> None:
    adapter = get_adapter("ndt")
    with pytest.raises(ConfigError, match=r"resolution must be in \[1.0, 10.0\], got 15"):
        adapter.start({"resolution": 15.0})  # type: ignore[attr-defined]
    wide = adapter.space.override({"resolution": {"high": 20.0}})
    odom = with_space(adapter, wide).start({"resolution": 15.0})  # type: ignore[attr-defined]
    assert odom.params["resolution"] == 15.0
    with pytest.raises(ConfigError, match="does not match the adapter's"):
        with_space(get_adapter("gicp"), wide)
