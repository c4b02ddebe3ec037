"""experiments/fidelity.py, run on a small finished run: the studies and the database of
helpers.results_db laid out as a pipeline run leaves them, one trial stopped after half of its
sequence; the frames run, the best RTE, the surrogate's figures, the coverage and the CPU by
stage."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from helpers.results_db import build_database, make_world
from helpers.scripts import load_script

from pipeline.trajectory import Trajectory, read_trajectory, write_trajectory
from pipeline.tuning.layout import trajectory_path, trials_table_path

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "fidelity.py"


def _stop(trials: Path, algorithm: str, sequence: str, trial: int, frames: int) -> None:
    """Trial ``trial`` of a per-sequence study stopped (pruned) after ``frames`` frames."""
    path = trials_table_path(trials, algorithm, sequence)
    table = pq.read_table(path)
    status = pc.if_else(pc.equal(table["trial"], trial), "pruned", table["status"])
    pq.write_table(table.set_column(table.schema.get_field_index("status"), "status", status),
                   path)
    traj_path = trajectory_path(trials, algorithm, sequence, trial)
    t = read_trajectory(traj_path)
    write_trajectory(traj_path, Trajectory(t.frames[:frames], t.stamps_ns[:frames],
                                           t.T_world_lidar[:frames]))


def _run(tmp_path: Path) -> Path:
    """A run folder: data/sequences (both sequences trained), results/{trials, fixed,
    adaptune.duckdb}, metrics/surrogate.json and timing.log."""
    world = make_world(tmp_path / "world")
    _stop(world.root / "trials", "gicp", "cave_0", 3, 30)
    build_database(world)
    run = tmp_path / "run"
    (run / "data" / "sequences").mkdir(parents=True)
    for name in world.gts:
        (run / "data" / "sequences" / f"{name}.mcap").symlink_to(world.root / "seq" /
                                                                 f"{name}.mcap")
    (run / "data" / "sequences" / "index.json").write_text(
        json.dumps({"train": sorted(world.gts)}))
    (run / "results").mkdir()
    for name in ("trials", "fixed"):
        (run / "results" / name).symlink_to(world.root / name)
    (run / "results" / "adaptune.duckdb").symlink_to(world.db)
    (run / "metrics").mkdir()
    (run / "metrics" / "surrogate.json").write_text(json.dumps(
        {"mae": 1.5, "rmse": 2.5, "regret_mean": 0.25}))
    (run / "timing.log").write_text("TIME trials wall 12.0 user 7.5 sys 0.5\n"
                                    "TIME fixed wall 4.0 user 2.0 sys 1.0\n")
    return run


def test_a_small_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _run(tmp_path)
    load_script(SCRIPT).main([str(run)])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"== {run}"
    studies = {line.split(" trials ")[0].strip(): line.split(" trials ")[1]
               for line in lines[1:5]}
    # cave_0 (60 frames): trials 0 and 2 whole, 1 failed (counted whole), 3 stopped at 30
    assert studies["gicp cave_0"] == "   4 pruned    1 failed   1 frames run  87.5 %  best 1 %"
    assert studies["gicp street_0"] == "   4 pruned    0 failed   1 frames run 100.0 %  best 1 %"
    assert studies["ndt cave_0"] == "   2 pruned    0 failed   1 frames run 100.0 %  best 1 %"
    assert studies["gicp __joint__"] == "   3 pruned    0 failed   1 frames run 100.0 %  best 1 %"
    assert lines[5] == "  median best RTE over training sequences: 1 %"
    assert lines[6] == "  per-sequence studies: frames run 95.8 % (mean), joint 100.0 %"
    assert lines[7] == "  surrogate LOSO: MAE 1.5, RMSE 2.5, regret 0.25"
    coverage = [line for line in lines if line.startswith("  coverage ")]
    # cave_0's scored frames (50 of 60 at L = 10 m): gicp's trials 0, 2 and 3 and ndt's 0
    # early, trial 3's rows gone by the last third; street_0: gicp's 0, 2 and 3 throughout
    assert coverage[0].startswith("  coverage cave_0: 50 frames, 2 trial sets; distinct trials "
                                  "a frame, first third 4.0, last third 3.0;")
    assert coverage[1].startswith("  coverage street_0: 35 frames, 1 trial sets; distinct "
                                  "trials a frame, first third 3.0, last third 3.0;")
    assert lines[-1] == "  CPU by stage [s]: trials 8, fixed 3"


def test_a_run_without_a_training_split_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match=r"run: no sequence folder with a training split"):
        load_script(SCRIPT).main([str(tmp_path / "run")])
