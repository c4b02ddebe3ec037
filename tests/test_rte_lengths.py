"""A sequence's own RTE length (issue 54: a ``data`` source's ``length_m``, in the sequence's
``SequenceInfo.length_m``) wins over base.length_m wherever the sequence is scored: ingest, a
joint study of sequences of different L (its trials, rungs and fingerprint), the results
database, the evaluate stage and ``metric rte``. Each figure is checked against
``pipeline.metrics.rte.per_frame_rte`` at the sequence's own L, computed here. Likewise a
source's own ``jump_limit_m`` wins over trials.jump_limit_m when a trial is checked for jumps."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers.source_inputs import write_kitti_poses, write_pcd
from helpers.tuning_settings import HALVING, settings

from pipeline.errors import ConfigError
from pipeline.geometry import rot_z
from pipeline.info import summarize_sequence
from pipeline.metrics.rte import per_frame_rte
from pipeline.sequence import SequenceReader, read_ground_truth
from pipeline.trajectory import read_trajectory
from pipeline.tuning.fingerprint import check_fingerprint, sequence_digest
from stages.cli import main

sys.path.insert(0, str(Path(__file__).parent))  # helpers, for the spawned trial workers

DRIFT = "helpers.tuning_adapters:drift"
BASE_LENGTH_M = 40.0
"""base.length_m: longer than either run (29 m), which only their own lengths can score."""
OWN = {"walk_a": 5.0, "walk_b": 12.0}


def _run(folder: Path, yaw_rate: float, seed: int, step_m: float = 1.0) -> None:
    """A scan folder of 30 frames, ``step_m`` apart along a curve: PCD scans, poses.txt (the
    LiDAR's poses, KITTI format), times.txt (10 Hz)."""
    scans = folder / "scans"
    scans.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (30, 1, 1))
    for k in range(1, 30):
        step = np.eye(4)
        step[:3, :3] = rot_z(yaw_rate)
        step[0, 3] = step_m
        T[k] = T[k - 1] @ step
    for k in range(30):
        write_pcd(scans / f"{k:06d}.pcd", rng.uniform(-10, 10, (40, 4)).astype(np.float32))
    write_kitti_poses(folder / "poses.txt", T)
    (folder / "times.txt").write_text("".join(f"{5 + 0.1 * k:.3f}\n" for k in range(30)))


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The two runs ingested by `adaptune ingest-set`, each with its own length_m."""
    root = tmp_path_factory.mktemp("lengths")
    sources = []
    for (name, length_m), yaw in zip(OWN.items(), (0.03, -0.05), strict=True):
        _run(root / name, yaw, seed=len(sources))
        sources.append({"kind": "folder", "path": f"{name}/scans", "name": name,
                        "poses": f"{name}/poses.txt", "times": f"{name}/times.txt",
                        "length_m": length_m})
    (root / "params.yaml").write_text(yaml.safe_dump(
        {"base": {"length_m": BASE_LENGTH_M}, "data": {"sources": sources}}))
    result = CliRunner().invoke(main, ["ingest-set", "--params", str(root / "params.yaml"),
                                       "--out", str(root / "recordings")])
    assert result.exit_code == 0, result.output
    return root / "recordings"


def _hand_rte(gt: np.ndarray, est: np.ndarray, length_m: float) -> np.ndarray:
    return per_frame_rte(gt, est, length_m)[0]


def _running(gt: np.ndarray, est: np.ndarray, frame: int, length_m: float) -> float:
    """Mean RTE [%] of the segments of ``length_m`` that end by ``frame`` (NaN: none)."""
    t = _hand_rte(gt[:frame + 1], est[:frame + 1], length_m)
    return float(np.mean(t[np.isfinite(t)])) if np.isfinite(t).any() else math.nan


def test_each_sequence_is_scored_at_its_own_length_from_trials_to_evaluate(
        recordings: Path, tmp_path: Path) -> None:
    from pipeline.database.store import build_database
    from pipeline.evaluate.runs import evaluate
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.metrics.section import DevkitSection
    from pipeline.odometry import run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.odometry.registry import build_adapter
    from pipeline.report.metrics import metrics
    from pipeline.trajectory import write_trajectory
    from pipeline.tuning.layout import rungs_folder, trajectory_path
    from pipeline.tuning.rung_board import RungBoard
    from pipeline.tuning.smbo import run_trials
    from pipeline.tuning.table import read_study, trials_path

    paths = [recordings / f"{name}.mcap" for name in OWN]
    gts = {name: read_ground_truth(recordings / f"{name}.mcap", "") for name in OWN}
    for name, length_m in OWN.items():
        with SequenceReader(recordings / f"{name}.mcap") as r:
            assert r.info.length_m == length_m and r.info.jump_limit_m is None
        details = summarize_sequence(recordings / f"{name}.mcap").details
        assert details["rte_length"] == f"{length_m:g} m (its own)"
        assert "jump_limit" not in details

    # a joint study (successive halving: rungs at 1/4, 1/2 and all of both sequences)
    s = settings(iterations=4, length_m=BASE_LENGTH_M, time_limit_s=None, **HALVING)
    results: list[Any] = []
    fixed = tmp_path / "fixed"
    run_trials(paths, fixed, s, seed=3, joint=True, progress=False,
               on_trial=lambda study, r: results.append(r))
    ests = {(name, r.trial): read_trajectory(
        trajectory_path(fixed, "drift", name, r.trial)).T_world_lidar
        for r in results for name in OWN if r.status == "ok"}
    ok = [r for r in results if r.status == "ok"]
    assert ok and len(results) == 4
    for r in ok:
        for name, length_m in OWN.items():
            t = _hand_rte(gts[name], ests[(name, r.trial)], length_m)
            assert r.rte_pct[name] == pytest.approx(float(np.nanmean(t)), rel=1e-12)
        assert r.objective == pytest.approx(np.mean(list(r.rte_pct.values())), rel=1e-12)
    points = s.stopping.checkpoints([30, 30])
    posted = RungBoard(str(rungs_folder(fixed, "drift", "__joint__"))).read(0)
    assert posted is not None and len(posted.values) == len(points) == 2  # 1/4, 1/2 of each
    for point, value in zip(points, posted.values, strict=True):
        hand = [_running(gts[n], ests[(n, 0)], f, OWN[n])
                for n, f in zip(OWN, point.frames, strict=True) if f >= 0]
        assert value == pytest.approx(np.nanmean(hand), rel=1e-12)
    fingerprint = read_study(trials_path(fixed, "drift", "__joint__"))
    assert fingerprint is not None and fingerprint["length_m"] == BASE_LENGTH_M
    assert [(d["name"], d["length_m"]) for d in fingerprint["sequences"]] == list(OWN.items())

    # the results database: rte_frames at each sequence's L
    db = tmp_path / "results.duckdb"
    build_database(db, recordings, {"fixed": fixed}, BASE_LENGTH_M,
                   DevkitSection(lengths_m=(5.0,), step_frames=5))
    import duckdb

    with duckdb.connect(str(db), read_only=True) as con:
        for name, length_m in OWN.items():
            rows = con.execute("SELECT frame, length_m, t_err_pct FROM rte_frames WHERE "
                               "sequence = ? AND trial = 0 ORDER BY frame", [name]).fetchall()
            t = _hand_rte(gts[name], ests[(name, 0)], length_m)
            assert {x[1] for x in rows} == {length_m}
            assert [x[0] for x in rows] == np.flatnonzero(np.isfinite(t)).tolist()
            np.testing.assert_allclose([x[2] for x in rows], t[np.isfinite(t)], rtol=1e-9)

    # the evaluate stage: baseline, fixed and adaptive at each sequence's L
    adapter = build_adapter(DRIFT)
    defaults = adapter.space.defaults()
    for path in paths:
        traj = run_sequence(adapter, path, defaults)
        folder = tmp_path / "adaptive" / path.stem
        Schedule.constant(defaults, len(traj)).write(folder / "schedule.parquet")
        write_trajectory(folder / "trajectory.parquet", traj, {"setting": "adaptive"})
        (folder / "run.json").write_text(json.dumps({"algorithm": DRIFT}))
    section = EvaluateSection(length_m=BASE_LENGTH_M, workers=1, splits=["train"],
                              devkit=DevkitSection(lengths_m=(5.0,), step_frames=5))
    ev = evaluate(paths, DRIFT, results[0].params, tmp_path / "adaptive", tmp_path / "ev",
                  section)
    m = metrics(ev, {})
    for name, length_m in OWN.items():
        for setting in ("baseline", "fixed", "adaptive"):
            est = ev.score(setting, name).trajectory.T_world_lidar
            np.testing.assert_array_equal(ev.score(setting, name).t_err_pct,
                                          _hand_rte(gts[name], est, length_m))
        assert m["sequences"][name]["length_m"] == length_m
    assert m["length_m"] == BASE_LENGTH_M


def test_metric_rte_takes_the_sequences_own_length(recordings: Path, tmp_path: Path) -> None:
    """Without --length, `metric rte` scores at the ground-truth sequence's own L; --length
    given is the one used; a ground truth without an L of its own needs --length."""
    from pipeline.odometry import run_sequence
    from pipeline.odometry.registry import build_adapter
    from pipeline.trajectory import write_trajectory

    seq = recordings / "walk_b.mcap"
    adapter = build_adapter(DRIFT)
    traj = run_sequence(adapter, seq, adapter.space.defaults())
    write_trajectory(tmp_path / "t.parquet", traj, {"sequence": str(seq)})
    gt = read_ground_truth(seq, "")
    for extra, length_m in (([], 12.0), (["--length", "7"], 7.0)):
        result = CliRunner().invoke(main, ["metric", "rte", str(seq), str(tmp_path / "t.parquet"),
                                           "--json", *extra])
        assert result.exit_code == 0, result.output
        got = json.loads(result.stdout)["rte"]
        t = _hand_rte(gt, traj.T_world_lidar, length_m)
        assert got["length_m"] == length_m
        assert got["t_err_pct"] == pytest.approx(float(np.nanmean(t)), rel=1e-12)
    poses = tmp_path / "gt.txt"
    write_kitti_poses(poses, gt)
    result = CliRunner().invoke(main, ["metric", "rte", str(poses), str(tmp_path / "t.parquet")])
    assert result.exit_code == 1 and "no RTE length of its own" in result.output
    assert "give --length" in result.output


def test_a_fingerprint_names_a_changed_own_length(recordings: Path) -> None:
    """A sequence's own L is in its digest (a resume at another L is refused, naming it); a
    sequence without one has no such key: the fingerprint it had before lengths existed."""
    path = recordings / "walk_a.mcap"
    plain = sequence_digest("walk_a", path)
    assert "length_m" not in plain
    stored = {"version": 1, "sequences": [plain | {"length_m": 5.0}]}
    now = {"version": 1, "sequences": [plain | {"length_m": 6.0}]}
    with pytest.raises(ConfigError, match="RTE length of sequence walk_a 6 m, stored 5 m"):
        check_fingerprint(stored, now, "t.parquet")
    with pytest.raises(ConfigError, match="walk_a none of its own, stored 5 m"):
        check_fingerprint(stored, {"version": 1, "sequences": [plain]}, "t.parquet")
    check_fingerprint(stored, {"version": 1, "sequences": [sequence_digest("walk_a", path, 5.0)]},
                      "t.parquet")


def test_a_sequences_own_jump_limit_wins_over_the_trials(tmp_path: Path) -> None:
    """A drive whose frames are 7 m apart (the drift adapter's steps: 5.7-8.1 m): with its own
    jump_limit_m 10 every trial runs; the same run without one fails every trial at
    trials.jump_limit_m 5. The limit is recorded in the MCAP, the ingest record and the study's
    fingerprint only where the source gives one."""
    from pipeline.tuning.smbo import run_trials
    from pipeline.tuning.table import read_study, trials_path

    _run(tmp_path / "drive", 0.01, seed=5, step_m=7.0)
    source = {"kind": "folder", "path": "drive/scans", "poses": "drive/poses.txt",
              "times": "drive/times.txt"}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(
        {"base": {"length_m": BASE_LENGTH_M},
         "data": {"sources": [source | {"name": "own", "jump_limit_m": 10.0},
                              source | {"name": "plain"}]}}))
    result = CliRunner().invoke(main, ["ingest-set", "--params", str(tmp_path / "params.yaml"),
                                       "--out", str(tmp_path / "seq"),
                                       "--record", str(tmp_path / "record.json")])
    assert result.exit_code == 0, result.output
    record = json.loads((tmp_path / "record.json").read_text())
    assert [s.get("jump_limit_m") for s in record["sources"]] == [10.0, None]
    assert "jump_limit_m" not in record["sources"][1]
    for name, limit in (("own", 10.0), ("plain", None)):
        with SequenceReader(tmp_path / "seq" / f"{name}.mcap") as r:
            assert r.info.jump_limit_m == limit
    assert summarize_sequence(tmp_path / "seq" / "own.mcap").details["jump_limit"] == \
        "10 m (its own)"
    assert "jump_limit" not in summarize_sequence(tmp_path / "seq" / "plain.mcap").details
    results: dict[str, list[Any]] = {"own": [], "plain": []}
    run_trials([tmp_path / "seq" / "own.mcap", tmp_path / "seq" / "plain.mcap"],
               tmp_path / "trials", settings(iterations=3, length_m=BASE_LENGTH_M,
                                             jump_limit_m=5.0, time_limit_s=None),
               seed=1, joint=False, progress=False,
               on_trial=lambda study, r: results[study.name].append(r))
    assert [r.status for r in results["own"]] == ["ok"] * 3
    for r in results["plain"]:
        assert r.status == "failed" and "implausible jump" in r.error, r.error
        assert "(jump_limit_m=5.0)" in r.error
    assert len(results["plain"]) == 3
    digests = {name: read_study(trials_path(tmp_path / "trials", "drift", name))["sequences"][0]
               for name in results}
    assert digests["own"]["jump_limit_m"] == 10.0 and "jump_limit_m" not in digests["plain"]
    import optuna

    from pipeline.tuning.optuna_export import export_optuna

    export_optuna([tmp_path / "trials"], tmp_path / "studies.db")
    attrs = {name: optuna.load_study(study_name=f"trials/drift/{name}",
                                     storage=f"sqlite:///{tmp_path / 'studies.db'}").user_attrs
             for name in results}
    assert attrs["own"]["sequence_jump_limits_m"] == {"own": 10.0}
    assert "sequence_jump_limits_m" not in attrs["plain"]
    assert "sequence_lengths_m" not in attrs["own"]
