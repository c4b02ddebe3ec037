"""The results database: rte_frames / rte_kitti in DuckDB agree with the numpy metrics; the
rte, query and export commands; bad input gives one line and exit code 1."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import duckdb
import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from helpers.evaluation_data import cli_fails
from helpers.results_db import KITTI_LENGTHS, LENGTH_M, World, build_database, make_world

from pipeline.database.store import frame_label_table
from pipeline.errors import InputError
from pipeline.metrics.kitti import kitti_errors
from pipeline.metrics.rte import per_frame_rte
from pipeline.posefile import read_kitti_poses, read_tum
from pipeline.sequence import SequenceReader
from pipeline.surrogates.rows import read_training_rows
from pipeline.trajectory import Trajectory, read_trajectory, write_trajectory
from pipeline.tuning.layout import read_trials_tables, trajectory_path
from schemas import SCHEMA_VERSION
from stages.cli import main


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    return build_database(make_world(tmp_path_factory.mktemp("world")))


def connect(world: World) -> duckdb.DuckDBPyConnection:
    return duckdb.connect(str(world.root / "adaptune.duckdb"), read_only=True)


def test_rte_frames_equal_per_frame_rte(world: World) -> None:
    con = connect(world)
    checked = 0
    for study, estimates in world.estimates.items():
        for (sequence, trial), est in estimates.items():
            got = con.execute("SELECT frame, end_frame, length_m, t_err_pct, r_err_deg_per_m "
                              "FROM rte_frames WHERE study = ? AND algorithm = 'gicp' "
                              "AND sequence = ? AND trial = ? ORDER BY frame",
                              [study, sequence, trial]).fetchnumpy()
            t_err, r_err = per_frame_rte(world.gts[sequence], est, LENGTH_M)
            has = np.flatnonzero(np.isfinite(t_err))
            assert np.array_equal(got["frame"], has)
            assert np.all(got["length_m"] == LENGTH_M)
            np.testing.assert_allclose(got["t_err_pct"], t_err[has], rtol=1e-9)
            np.testing.assert_allclose(got["r_err_deg_per_m"], np.degrees(r_err[has]),
                                       rtol=1e-9, atol=1e-9)
            checked += 1
    # ok trials only: trial 1 failed without a trajectory
    assert checked == 2 * 3 + 2 * 2 + 2 * 2


def test_segment_end_after_standstill(world: World) -> None:
    # frames 11..14 of every sequence stand still (same path distance as frame 10)
    con = connect(world)
    gt = world.gts["cave_0"]
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1))])
    assert dist[10] == dist[14]
    ends = dict(con.execute("SELECT frame, end_frame FROM rte_frames WHERE study = 'trials' "
                            "AND algorithm = 'gicp' AND sequence = 'cave_0' AND trial = 0"
                            ).fetchall())
    for i, j in ends.items():
        assert dist[j] > dist[i] + LENGTH_M and dist[j - 1] <= dist[i] + LENGTH_M, (i, j)
    # frame 0's segment ends on the first frame of the standstill, not on one of its copies
    assert ends[0] == 10 and dist[11] == dist[10]


def test_rte_kitti_equals_devkit_segments(world: World) -> None:
    con = connect(world)
    est = world.estimates["trials"][("cave_0", 2)]
    got = con.execute("SELECT first_frame, last_frame, length_m, t_err, r_err FROM rte_kitti "
                      "WHERE study = 'trials' AND algorithm = 'gicp' AND sequence = 'cave_0' "
                      "AND trial = 2 ORDER BY first_frame, length_m").fetchnumpy()
    seg = kitti_errors(world.gts["cave_0"], est, KITTI_LENGTHS)
    assert len(seg) > 0
    assert np.array_equal(got["first_frame"], seg.first_frame)
    assert np.array_equal(got["last_frame"], seg.last_frame)
    np.testing.assert_allclose(got["t_err"], seg.t_err, rtol=1e-9)
    np.testing.assert_allclose(got["r_err"], seg.r_err, rtol=1e-7, atol=1e-12)


def test_trials_table_and_summary(world: World) -> None:
    con = connect(world)
    cols = [r[0] for r in con.execute("DESCRIBE trials").fetchall()]
    assert cols[:9] == ["study", "algorithm", "sequence", "trial", "status", "error", "objective",
                         "seed", "params_json"]
    assert cols[-2:] == ["mean_rte_pct", "rte_frames"]
    assert set(cols[9:-2]) == {"p_max_corr_m", "p_kf_m", "p_resolution_m"}
    rows = con.execute("SELECT study, algorithm, sequence, trial, status, mean_rte_pct, "
                       "rte_frames, p_resolution_m FROM trials ORDER BY ALL").fetchall()
    assert len(rows) == 4 * 2 + 3 + 2 + 3 * 2  # trials, fixed, ndt trials, portfolio
    for study, algorithm, sequence, trial, status, mean, n, p_res in rows:
        if status == "failed":
            assert mean is None and n == 0
            continue
        if algorithm == "ndt":
            assert p_res == float(trial)
            continue
        assert p_res is None
        seqs = world.gts if sequence == "__joint__" else [sequence]
        errs = np.concatenate([per_frame_rte(world.gts[s], world.estimates[study][(s, trial)],
                                             LENGTH_M)[0] for s in seqs])
        errs = errs[np.isfinite(errs)]
        assert n == len(errs)
        assert mean == pytest.approx(errs.mean(), rel=1e-9)


def test_sequences_labels_views_and_schema_info(world: World) -> None:
    con = connect(world)
    seqs = con.execute("SELECT sequence, frames, split FROM sequences ORDER BY 1").fetchall()
    assert seqs == [("cave_0", 60, "train"), ("street_0", 45, "validation")]
    assert con.execute("SELECT label FROM frame_labels WHERE sequence = 'cave_0' AND frame = 20"
                       ).fetchone() == ("open",)
    info = dict(con.execute("SELECT name, version FROM schema_info").fetchall())
    assert info == {"schema_version": SCHEMA_VERSION, "tables.sql": SCHEMA_VERSION,
                    "views.sql": SCHEMA_VERSION}
    view_cols = [r[0] for r in con.execute("DESCRIBE surrogate_rows").fetchall()]
    assert view_cols[:4] == ["algorithm", "sequence", "trial", "frame"]
    assert view_cols[4:14] == [f"e{i}" for i in range(10)]
    assert view_cols[-1] == "y" and {"p_kf_m", "p_max_corr_m"} <= set(view_cols)
    n_rows = con.execute("SELECT count(*) FROM surrogate_rows").fetchone()[0]
    n_expected = con.execute("SELECT count(*) FROM rte_frames r JOIN trials t USING "
                             "(study, algorithm, sequence, trial) WHERE r.study = 'trials' "
                             "AND t.status = 'ok'").fetchone()[0]
    assert n_rows == n_expected > 0
    dup = con.execute("SELECT count(*) FROM (SELECT algorithm, sequence, trial, frame FROM "
                      "surrogate_rows GROUP BY ALL HAVING count(*) > 1)").fetchone()[0]
    assert dup == 0
    assert con.execute("SELECT count(*) FROM descriptors").fetchone()[0] == 0


def test_portfolio_rows_hold_every_member_at_every_frame(world: World) -> None:
    """The portfolio selector's rows: every member of the portfolio study at every frame any
    member scored, an ok member at its per-frame RTE, the failed one (trial 1, no trajectory)
    at its objective, the failure penalty, on all of those frames; read_training_rows reads them
    with surrogate.rows = portfolio."""
    from pipeline.odometry.base import ParameterSpace, ParamSpec

    con = connect(world)
    space = ParameterSpace((ParamSpec("max_corr_m", 0, 10, 1), ParamSpec("kf_m", 0, 10, 1)))
    for sequence, gt in world.gts.items():
        t_err = {trial: per_frame_rte(gt, world.estimates["portfolio"][(sequence, trial)],
                                      LENGTH_M)[0] for trial in (0, 2)}
        frames = np.flatnonzero(np.isfinite(t_err[0]))
        assert len(frames) > 0
        for trial in (0, 1, 2):
            got = con.execute("SELECT frame, y, p_max_corr_m FROM portfolio_rows WHERE "
                              "algorithm = 'gicp' AND sequence = ? AND trial = ? ORDER BY frame",
                              [sequence, trial]).fetchnumpy()
            assert np.array_equal(got["frame"], frames)
            assert np.all(got["p_max_corr_m"] == float(trial))
            want = np.full(len(frames), 100.0) if trial == 1 else t_err[trial][frames]
            np.testing.assert_allclose(got["y"], want, rtol=1e-9)
    _, _, rows = read_training_rows(world.root / "adaptune.duckdb", "gicp", lambda a: space,
                                    "portfolio")
    assert len(rows.y) == 3 * sum(np.isfinite(per_frame_rte(gt, gt, LENGTH_M)[0]).sum()
                                  for gt in world.gts.values())
    assert np.sort(rows.y)[-1] == 100.0
    _, _, trial_rows = read_training_rows(world.root / "adaptune.duckdb", "gicp",
                                          lambda a: space)
    assert not np.any(trial_rows.y == 100.0)  # the SMBO's failed trials give no rows


def test_read_trials_tables_unions_parameters(world: World) -> None:
    table = read_trials_tables(world.root / "trials")
    assert table.column_names[:3] == ["algorithm", "sequence", "trial"]
    assert {"p_kf_m", "p_max_corr_m", "p_resolution_m"} <= set(table.column_names)
    assert table.num_rows == 4 * 2 + 2


def test_rte_stage_bad_inputs_leave_no_database(world: World, tmp_path: Path) -> None:
    db = tmp_path / "out.duckdb"
    cli_fails(world.args(db, "--descriptors", str(tmp_path / "missing.parquet")), "missing.parquet")
    assert not db.exists()
    bad_params = tmp_path / "params.yaml"
    bad_params.write_text("base:\n  length_m: -1\n")
    args = world.args(db)
    args[args.index("--params") + 1] = str(bad_params)
    cli_fails(args, "base.length_m", "greater than 0")
    assert not db.exists()
    assert not list(tmp_path.glob(".out.duckdb*"))


def test_rte_without_the_optional_inputs_builds_a_database(world: World,
                                                           tmp_path: Path) -> None:
    """Issue 32, cases 7 and 8: without --environment (or without any study) views.sql's
    COLUMNS('^e[0-9]+$') matched nothing: a BinderException traceback (and `make bench`
    stopped there). The database is built, its surrogate_rows view without those columns,
    which holds no rows (the surrogate stage says so)."""
    db = tmp_path / "bare.duckdb"
    result = CliRunner().invoke(main, world.args(db))
    assert result.exit_code == 0, (result.output, result.exception)
    with duckdb.connect(str(db), read_only=True) as con:
        cols = [r[0] for r in con.execute("DESCRIBE surrogate_rows").fetchall()]
    assert cols[:4] == ["algorithm", "sequence", "trial", "frame"] and cols[-1] == "y"
    assert not [c for c in cols if c[0] == "e" and c[1:].isdigit()]
    with pytest.raises(InputError, match="no surrogate rows"):
        read_training_rows(db, "gicp", lambda a: SimpleNamespace(names=["max_corr_m", "kf_m"]))
    nothing = tmp_path / "nothing.duckdb"
    result = CliRunner().invoke(main, ["rte", "--params", str(world.params), "--sequences",
                                       str(world.root / "seq"), "--db", str(nothing)])
    assert result.exit_code == 0, (result.output, result.exception)


def test_rte_stage_rejects_nan_and_short_trajectories(world: World, tmp_path: Path) -> None:
    import shutil

    trials = tmp_path / "trials"
    shutil.copytree(world.root / "trials", trials)
    path = trajectory_path(trials, "gicp", "cave_0", 2)
    traj = read_trajectory(path)
    poses = traj.T_world_lidar.copy()
    poses[5, 0, 3] = np.nan
    write_trajectory(path, Trajectory(traj.frames, traj.stamps_ns, poses))
    db = tmp_path / "out.duckdb"
    args = ["rte", "--params", str(world.params), "--sequences", str(world.root / "seq"),
            "--trials", str(trials), "--db", str(db)]
    cli_fails(args, "trial=2", "non-finite")
    write_trajectory(path, Trajectory(traj.frames[:-3], traj.stamps_ns[:-3],
                                      traj.T_world_lidar[:-3]))
    cli_fails(args, "trial=2", "57 poses", "60 frames")
    assert not db.exists()


def test_query_cli(world: World, tmp_path: Path) -> None:
    db = str(world.root / "adaptune.duckdb")
    sql = "SELECT sequence, count(*) AS n FROM rte_frames GROUP BY ALL ORDER BY 1"
    result = CliRunner().invoke(main, ["query", "--db", db, sql])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].split() == ["sequence", "n"] and lines[2].split()[0] == "cave_0"
    result = CliRunner().invoke(main, ["query", "--db", db, sql, "--format", "json"])
    assert [r["sequence"] for r in json.loads(result.output)] == ["cave_0", "street_0"]
    out = tmp_path / "q.parquet"
    result = CliRunner().invoke(main, ["query", "--db", db, sql, "--format", "parquet",
                                       "--out", str(out)])
    assert result.exit_code == 0 and pq.read_table(out).num_rows == 2
    result = CliRunner().invoke(main, ["query", "--db", db, sql, "--format", "csv"])
    assert result.output.splitlines()[0] == '"sequence","n"'


def test_query_cli_errors(world: World, tmp_path: Path) -> None:
    db = str(world.root / "adaptune.duckdb")
    cli_fails(["query", "--db", db, "SELEC 1"], "syntax error")
    cli_fails(["query", "--db", db, "SELECT nope FROM trials"], "nope")
    cli_fails(["query", "--db", db, "DROP TABLE trials"], "read-only")
    cli_fails(["query", "--db", str(tmp_path / "none.duckdb"), "SELECT 1"], "none.duckdb",
              "no such database")
    out = tmp_path / "x.csv"
    cli_fails(["query", "--db", db, "SELEC 1", "--format", "csv", "--out", str(out)], "syntax")
    assert not out.exists()


def test_export_cli_round_trip(world: World, tmp_path: Path) -> None:
    src = trajectory_path(world.root / "trials", "gicp", "cave_0", 0)
    traj = read_trajectory(src)
    for fmt in ("kitti", "tum"):
        out = tmp_path / f"t.{fmt}"
        result = CliRunner().invoke(main, ["export", str(src), "--format", fmt, "--out", str(out),
                                           "--anchor", "identity"])
        assert result.exit_code == 0, result.output
    np.testing.assert_allclose(read_kitti_poses(tmp_path / "t.kitti"), traj.T_world_lidar,
                               atol=1e-10)
    stamps, poses = read_tum(tmp_path / "t.tum")
    np.testing.assert_allclose(poses, traj.T_world_lidar, atol=1e-10)
    np.testing.assert_allclose(stamps, traj.stamps_ns / 1e9, rtol=0, atol=1e-9)
    cli_fails(["export", str(tmp_path / "none.parquet"), "--format", "tum", "--out",
              str(tmp_path / "n.tum")], "none.parquet")
    assert not (tmp_path / "n.tum").exists()
    # anchored at the ground truth (the default) it needs the trajectory's sequence
    cli_fails(["export", str(src), "--format", "kitti", "--out", str(tmp_path / "a.kitti")],
              "its sequence is unknown", "--sequence SEQ.mcap")
    seq = world.root / "seq" / "cave_0.mcap"
    result = CliRunner().invoke(main, ["export", str(src), "--format", "kitti", "--out",
                                       str(tmp_path / "a.kitti"), "--sequence", str(seq)])
    assert result.exit_code == 0, result.output
    anchored = read_kitti_poses(tmp_path / "a.kitti")
    np.testing.assert_allclose(anchored[0], SequenceReader(seq).ground_truth()[0], atol=1e-9)
    np.testing.assert_allclose(np.linalg.inv(anchored[0]) @ anchored,
                               np.linalg.inv(traj.T_world_lidar[0]) @ traj.T_world_lidar,
                               atol=1e-9)
    cli_fails(["export", str(src), "--format", "kitti", "--out", str(tmp_path / "c.kitti"),
               "--sequence", str(seq), "--frame", "kitti-camera"], "no camera calibration",
              "--calib")


def test_frame_labels_keep_the_later_label_at_overlaps_and_clip_to_the_sequence() -> None:
    """The frame_labels rows of a sequence equal what row-by-row INSERT OR REPLACE gave: every
    frame of every inclusive range inside the sequence, the later range winning an overlap."""
    labels = [(-3, 4, "cave"), (4, 9, "open"), (7, 7, "street"), (12, 30, "cave"), (6, 2, "open")]
    table = frame_label_table("w", 15, labels)
    expected: dict[int, str] = {}
    for start, end, label in labels:
        expected.update({f: label for f in range(15) if start <= f <= end})
    assert table.column_names == ["sequence", "frame", "label"]
    pairs = zip(table["frame"].to_pylist(), table["label"].to_pylist(), strict=True)
    assert dict(pairs) == expected
    assert table["frame"].to_pylist() == sorted(expected)
    assert set(table["sequence"].to_pylist()) == {"w"}
    assert frame_label_table("w", 5, []).num_rows == 0


def test_a_database_of_some_sequences_holds_them_and_the_joint_study_only(
        world: World, tmp_path: Path) -> None:
    """``build_database(sequences=...)`` (a fold of the real-data study trains on some of a
    folder's units): the sequences, trials and trajectories of those and of the joint study;
    the others' rows are not there."""
    from pipeline.database.store import build_database as build
    from pipeline.metrics.section import DevkitSection
    from pipeline.tuning.layout import JOINT_SEQUENCE

    db = tmp_path / "some.duckdb"
    build(db, world.root / "seq", {"trials": world.root / "trials",
                                   "fixed": world.root / "fixed"},
          LENGTH_M, DevkitSection.model_validate({"lengths_m": list(KITTI_LENGTHS)}),
          sequences=["cave_0"])
    con = duckdb.connect(str(db), read_only=True)
    try:
        def names(sql: str) -> set[str]:
            return {r[0] for r in con.execute(sql).fetchall()}

        assert names("SELECT sequence FROM sequences") == {"cave_0"}
        assert names("SELECT DISTINCT sequence FROM trials") == {"cave_0", JOINT_SEQUENCE}
        assert names("SELECT DISTINCT sequence FROM rte_frames") == {"cave_0"}
        every = connect(world)
        try:
            assert every.execute("SELECT count(DISTINCT sequence) FROM rte_frames").fetchone() \
                == (2,)
        finally:
            every.close()
    finally:
        con.close()
