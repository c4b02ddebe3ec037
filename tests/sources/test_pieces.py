"""A ``data`` source's ``pieces`` and ``length_m`` (issue 54): a run cut where a time step or a
reference step exceeds a limit, each piece its own sequence ``<name>_p<k>`` at the source's RTE
length, a piece too short for it dropped with one line in the ingest record, the source refused
by name only when nothing remains."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers.source_inputs import write_kitti_poses, write_pcd

from pipeline.sequence import SequenceReader
from stages.cli import main

STEPS_M = [1.0] * 3 + [1.0] + [1.0] * 4 + [20.0] + [0.5] * 2
"""Steps between the 12 frames: 0-3 (3 m), a time gap, 4-8 (4 m), a 20 m gap, 9-11 (1 m)."""
DT_S = [0.1] * 3 + [5.0] + [0.1] * 4 + [0.1] + [0.1] * 2


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A scan folder of 12 frames with poses.txt (LiDAR poses) and times.txt."""
    folder = tmp_path_factory.mktemp("run")
    scans = folder / "scans"
    scans.mkdir()
    rng = np.random.default_rng(5)
    points = [rng.uniform(-20, 20, (50, 4)).astype(np.float32) for _ in range(12)]
    for k, pts in enumerate(points):
        pts[:, 3] = np.abs(pts[:, 3]) / 20
        write_pcd(scans / f"{k:06d}.pcd", pts)
    x = np.concatenate([[0.0], np.cumsum(STEPS_M)])
    T = np.tile(np.eye(4), (12, 1, 1))
    T[:, 0, 3] = x
    t_s = 100.0 + np.concatenate([[0.0], np.cumsum(DT_S)])
    write_kitti_poses(folder / "poses.txt", T)
    (folder / "times.txt").write_text("".join(f"{t:.6f}\n" for t in t_s))
    return {"folder": folder, "points": points, "T": T,
            "stamps_ns": np.round(t_s * 1e9).astype(np.int64)}


def ingest(tmp_path: Path, run: dict[str, Any], base_length_m: float = 25.0,
           **options: Any) -> tuple[int, str, Path]:
    """``adaptune ingest-set`` of the run as a folder source named ``walk`` with ``options``."""
    source = {"kind": "folder", "path": str(run["folder"] / "scans"), "name": "walk",
              "poses": str(run["folder"] / "poses.txt"),
              "times": str(run["folder"] / "times.txt"), **options}
    tmp_path.mkdir(exist_ok=True)
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"base": {"length_m": base_length_m},
                                      "data": {"sources": [source]}}))
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["ingest-set", "--params", str(params), "--out", str(out),
                                       "--record", str(tmp_path / "record.json")])
    return result.exit_code, result.output, out


def test_a_run_is_cut_at_its_gaps_and_a_short_piece_is_dropped_with_a_line(
        tmp_path: Path, run: dict[str, Any]) -> None:
    code, output, out = ingest(tmp_path, run, length_m=2.0,
                               pieces={"max_time_step_s": 1.0, "max_step_m": 5.0})
    assert code == 0, output
    dropped = ("walk_p2: frames 9-11 of 12, 1.0 m of ground truth, not longer than its RTE "
               "length 2 m: dropped")
    assert dropped in output
    assert json.loads((out / "index.json").read_text()) == {
        "train": ["walk_p0", "walk_p1"], "validation": []}
    record = json.loads((tmp_path / "record.json").read_text())
    (source,) = record["sources"]
    assert source["length_m"] == 2.0 and source["dropped"] == [dropped]
    assert [(s["name"], s["frames"], s["run_frames"]) for s in source["sequences"]] == [
        ("walk_p0", 4, "0-3 of 12"), ("walk_p1", 5, "4-8 of 12")]
    assert [s["path_m"] for s in source["sequences"]] == pytest.approx([3.0, 4.0])
    for name, first, stop in (("walk_p0", 0, 4), ("walk_p1", 4, 9)):
        with SequenceReader(out / f"{name}.mcap") as r:
            assert r.info.length_m == 2.0 and r.info.name == name
            assert r.info.extra["piece_of"] == "walk"
            assert r.info.extra["run_frames"] == f"{first}-{stop - 1} of 12"
            np.testing.assert_array_equal(r.stamps_ns, run["stamps_ns"][first:stop])
            np.testing.assert_allclose(r.ground_truth(), run["T"][first:stop], atol=1e-9)
            for scan in r:
                np.testing.assert_array_equal(scan.points_lidar,
                                              run["points"][first + scan.frame])
    assert not (out / "walk_p2.mcap").exists() and not (out / "walk.mcap").exists()


def test_each_limit_cuts_alone(tmp_path: Path, run: dict[str, Any]) -> None:
    """The time step alone cuts at the 5 s gap; the reference step alone at the 20 m one; a
    step equal to its limit is no cut. Without length_m the pieces take base.length_m."""
    code, output, out = ingest(tmp_path / "t", run, base_length_m=2.5,
                               pieces={"max_time_step_s": 1.0})
    assert code == 0, output
    assert json.loads((out / "index.json").read_text())["train"] == ["walk_p0", "walk_p1"]
    with SequenceReader(out / "walk_p1.mcap") as r:
        assert len(r) == 8 and r.info.length_m is None
    code, output, out = ingest(tmp_path / "s", run, base_length_m=2.5,
                               pieces={"max_step_m": 20.0})
    assert code == 0, output
    assert json.loads((out / "index.json").read_text())["train"] == ["walk_p0"]
    code, output, out = ingest(tmp_path / "m", run, base_length_m=2.5,
                               pieces={"max_step_m": 19.9})
    assert json.loads((out / "index.json").read_text())["train"] == ["walk_p0"]
    assert "walk_p1: frames 9-11 of 12, 1.0 m" in output


def test_a_source_is_refused_by_name_only_when_nothing_remains(
        tmp_path: Path, run: dict[str, Any]) -> None:
    code, output, out = ingest(tmp_path, run, length_m=4.0,
                               pieces={"max_time_step_s": 1.0, "max_step_m": 5.0})
    assert code == 1 and output.count("\n") == 1, output
    assert "(sequence walk): no piece's ground truth runs longer than its RTE length 4 m" in output
    assert "3 pieces, the longest 4.0 m" in output
    assert not out.exists() or not list(out.iterdir())
    assert not (tmp_path / "record.json").exists()


def test_the_sources_own_length_wins_over_base_length_m(
        tmp_path: Path, run: dict[str, Any]) -> None:
    """Without pieces: the whole run (29 m) is one sequence ``walk``; its own length_m is the
    one it is checked at and records; base.length_m (50 m) would have refused it."""
    code, output, out = ingest(tmp_path / "own", run, base_length_m=50.0, length_m=10.0)
    assert code == 0, output
    with SequenceReader(out / "walk.mcap") as r:
        assert r.info.length_m == 10.0 and len(r) == 12
    code, output, _ = ingest(tmp_path / "short", run, base_length_m=5.0, length_m=30.0)
    assert code == 1 and "ground truth runs 29.0 m, not longer than length_m=30.0" in output
    assert "the recording's own length_m" in output


@pytest.mark.parametrize("options, message", [
    ({"pieces": {}}, "pieces: pieces needs max_time_step_s or max_step_m"),
    ({"pieces": {"max_step_m": 0}}, "pieces.max_step_m: Input should be greater than 0, got 0"),
    ({"pieces": {"max_time_step_s": float("inf")}}, "pieces.max_time_step_s"),
    ({"pieces": {"max_gap_m": 3}}, "pieces.max_gap_m: unknown parameter"),
    ({"length_m": -2}, "length_m: Input should be greater than 0, got -2"),
    ({"jump_limit_m": 0}, "jump_limit_m: Input should be greater than 0, got 0"),
])
def test_bad_pieces_and_lengths_are_one_line(tmp_path: Path, run: dict[str, Any],
                                             options: dict[str, Any], message: str) -> None:
    code, output, _ = ingest(tmp_path, run, **options)
    assert code == 1 and output.count("\n") == 1 and message in output, output
