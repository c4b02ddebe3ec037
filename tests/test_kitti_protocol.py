"""The KITTI protocol preset (the paper's Table II) end to end through DVC, on real KITTI scans.

What `make kitti` runs: `adaptune kitti-preset` prints the `dvc exp run --set-param`s, `dvc exp
run` takes them (a git + DVC project), `adaptune kitti-table` lays the metrics out. Here on the
10-frame slices of ../shared/data (01, 04 train; 06, 10 test), 3 + 2 trials, L = 1.5 m (sequence
10's 10 frames run 1.7 m), the stages up to evaluate and generalize, which the protocol runs
without a world (its suite's test is in test_pipeline_dvc.py).

The same experiment runs docs/usage.md's kiss_icp line and its Dask-cluster line (a scheduler
and a worker on 127.0.0.1, up for the module), and its KITTI line is checked against it: one
KITTI pipeline for the suite (test_pipeline_dvc.py runs the documented lines on simulated
worlds). KISS-ICP on coarse voxels (KISS_COARSE): a voxel of 0.2-0.6 m made a run up to 20x
dearer; what is checked does not depend on it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest
import yaml
from click.testing import CliRunner
from helpers.dask_cluster import tcp_cluster
from test_pipeline_dvc import (
    BIN,
    REPO,
    TCP_LINE,
    documented_variations,
    dvc,
    git,
    project,
    tiny,
    tiny_params,
)

from pipeline.outputs import read_summary
from stages.cli import main

pytestmark = pytest.mark.slow

KITTI_L_M = 1.5
"""L here: sequence 10's first 10 frames run 1.7 m, and a sequence not longer than L has no
RTE score (evaluate refuses it; with the tiny params' 4 m it dropped out of its split)."""

KISS_COARSE = "+trials.space.voxel_size={low: 1.0, high: 4.0, default: 3.5}"
"""kiss_icp's searched voxel size from params.yaml, wider than its built-in [0.2, 3] m: every
later stage must take it from the trials output (the baseline runs at 3.5 m); and coarse, so
that a run costs about a second (a voxel of 0.23 m took 26 s on sequence 04's 10 scans)."""


def _preset(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["kitti-preset", *args])
    return result.exit_code, result.output


class Protocol(NamedTuple):
    root: Path
    log: str
    """`dvc exp run`'s output."""
    preset: list[str]
    """The preset's ``--set-param`` arguments."""


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A Dask scheduler and one worker on 127.0.0.1 (docs/usage.md's cluster section), up for
    the module: the protocol's trials run on it, its determinism check runs them again there."""
    with tcp_cluster(tmp_path_factory.mktemp("dask"), 1) as (address, _):
        yield address


@pytest.fixture(scope="module")
def protocol(kitti_root: Path, cluster: str,
             tmp_path_factory: pytest.TempPathFactory) -> Protocol:
    """A git + DVC project on the tiny params, turned into the KITTI protocol and run as `make
    kitti` runs it: the evaluate and generalize targets (the simulated worlds of the simulate
    stage are not made; the generalize stage runs no world); with docs/usage.md's kiss_icp line
    and its cluster line (one trial in flight: the search reacts to every finished trial)."""
    p = tiny_params()
    p["descriptors"]["range_bins"] = 10  # the default width here
    root = project(tmp_path_factory.mktemp("kitti"), p)
    git(root, "add", "-A")
    git(root, "commit", "-qm", "tiny project")
    args = subprocess.run(
        [str(BIN / "adaptune"), "kitti-preset", "--root", str(kitti_root), "--train", "01,04",
         "--test", "06,10", "--iterations", "3", "--joint-iterations", "2",
         "--length-m", str(KITTI_L_M), "--kitti-lengths-m", "2,4", "--replicas", "1"],
        cwd=root, check=True, capture_output=True, text=True).stdout.splitlines()
    lines = documented_variations()
    log = dvc(root, "exp", "run", *args, *lines["trials.algorithm=kiss_icp"],
              *tiny(lines[TCP_LINE], **{"trials.dask": cluster, "trials.workers": "1"}),
              "-S", KISS_COARSE, "evaluate", "generalize")
    assert "Running stage 'ingest'" in log and "Running stage 'simulate'" not in log
    assert "Running stage 'generalize'" in log
    return Protocol(root, log, args)


def test_the_preset_sets_the_protocol(protocol: Protocol, kitti_root: Path) -> None:
    params = yaml.safe_load((protocol.root / "params.yaml").read_text())
    assert params["base"] | {"seed": 0} == {"seed": 0, "length_m": KITTI_L_M,
                                            "sequences": "data/recordings"}
    root = str(kitti_root.resolve())
    assert params["data"] == {"sources": [
        {"kind": "kitti", "path": root, "sequences": ["01", "04"], "split": "train"},
        {"kind": "kitti", "path": root, "sequences": ["06", "10"], "split": "validation"}]}
    assert params["evaluate"]["splits"] == ["validation", "train"]
    assert params["evaluate"]["replicas"] == 1
    assert (params["trials"]["iterations"], params["trials"]["startup_trials"],
            params["fixed"]["iterations"]) == (3, 2, 2)
    assert params["devkit"]["lengths_m"] == [2, 4] and "kitti_lengths_m" not in params["evaluate"]
    assert params["generalize"]["worlds"] == 0
    lock = yaml.safe_load((protocol.root / "dvc.lock").read_text())["stages"]
    assert any(d["path"] == "data/recordings" for d in lock["trials"]["deps"])


def test_the_documented_kitti_line_sets_what_the_preset_set(protocol: Protocol, kitti_root: Path,
                                                            tmp_path: Path) -> None:
    """docs/usage.md's KITTI line (its path, sequences and L those of this run), applied as `dvc
    exp run` applies it, selects the data this experiment ran on: the keys it sets and
    base.sequences are the preset's."""
    path = kitti_root.resolve()
    sources = (f"[{{kind: kitti, path: '{path}', split: train, sequences: ['01','04']}}, "
               f"{{kind: kitti, path: '{path}', split: validation, sequences: ['06','10']}}]")
    line = tiny(documented_variations()["kitti"], **{"base.length_m": str(KITTI_L_M),
                                                     "data.sources": sources})
    documented = overrides("\n".join(line[1::2]), tmp_path)
    preset = overrides("\n".join(protocol.preset), tmp_path)
    for key in ("base", "data"):
        assert documented[key] == preset[key], key
    assert preset["base"]["sequences"] == "data/recordings"
    assert preset["data"]["sources"][0]["path"] == str(path)


def test_every_stage_ran_on_kitti_at_the_new_length(protocol: Protocol) -> None:
    """Ingest and every stage up to evaluate ran, on the preset's L: the stages that read
    base.length_m recorded it, and the RTE of the database is at that L only."""
    import duckdb

    from pipeline.sequence import SequenceReader

    for stage in ("ingest", "descriptors", "trials", "fixed", "rte", "surrogate", "adaptive",
                  "evaluate"):
        assert f"Running stage '{stage}'" in protocol.log
    for seq in ("01", "04", "06", "10"):
        with SequenceReader(protocol.root / f"data/recordings/{seq}.mcap") as reader:
            assert len(reader) == 10 and reader.info.sensor != "unknown"
    lock = yaml.safe_load((protocol.root / "dvc.lock").read_text())["stages"]
    for stage in ("trials", "fixed", "rte", "evaluate"):
        assert lock[stage]["params"]["params.yaml"]["base.length_m"] == KITTI_L_M
    con = duckdb.connect(str(protocol.root / "results/adaptune.duckdb"), read_only=True)
    try:
        lengths = con.execute("SELECT DISTINCT length_m FROM rte_frames").fetchall()
    finally:
        con.close()
    assert lengths == [(KITTI_L_M,)]
    assert read_summary(protocol.root / "metrics/evaluation.json")["length_m"] == KITTI_L_M


def test_the_trials_ran_on_the_cluster(protocol: Protocol, cluster: str) -> None:
    """The documented cluster line: kiss_icp's trials went to the scheduler at its address."""
    from distributed import Client

    params = yaml.safe_load((protocol.root / "params.yaml").read_text())
    assert (params["trials"]["algorithm"], params["trials"]["dask"]) == ("kiss_icp", cluster)
    with Client(cluster, timeout="20s") as client:
        transitions = client.run_on_scheduler(
            lambda dask_scheduler: dask_scheduler.transition_counter)
    assert transitions > 0


def test_train_and_test_sequences_are_scored(protocol: Protocol) -> None:
    from pipeline.evaluate.result import SETTINGS

    root = protocol.root
    for seq in ("01", "04", "06", "10"):
        assert (root / f"results/adaptive/{seq}/trajectory.parquet").is_file()
    m = read_summary(root / "metrics/evaluation.json")
    assert m["algorithm"] == "kiss_icp" and m["headline_split"] == "validation"
    assert {s: v["sequences"] for s, v in m["splits"].items()} == {
        "validation": ["06", "10"], "train": ["01", "04"]}
    assert {n: s["split"] for n, s in m["sequences"].items()} == {
        "06": "validation", "10": "validation", "01": "train", "04": "train"}
    assert m["rte_pct"] == m["splits"]["validation"]["rte_pct"]
    assert all(0 < v < 50 for v in m["rte_pct"].values())
    assert m["params"]["baseline"]["voxel_size"] == 3.5
    model = json.loads((root / "model/manifest.json").read_text())
    (voxel,) = [s for s in model["parameter_space"] if s["name"] == "voxel_size"]
    assert (voxel["high"], voxel["default"]) == (4.0, 3.5)
    for split in m["splits"].values():  # the devkit pools the segments of the split
        for s in SETTINGS:
            per = [m["sequences"][n]["kitti"][s] for n in split["sequences"]]
            n = sum(k["segments"] for k in per)
            assert n == split["kitti"][s]["segments"] > 0
            pooled = sum(k["t_err_pct"] * k["segments"] for k in per if k["segments"]) / n
            assert split["kitti"][s]["t_err_pct"] == pytest.approx(pooled, rel=1e-12)
    report = (root / "report/report.md").read_text()
    assert "| kiss_icp | baseline |" in report and "## Per split" in report


def test_the_protocol_carries_no_stale_suite(protocol: Protocol) -> None:
    """The experiment's generalize stage ran no world: its metrics are empty, its record and
    figure say so (not the tiny project's suite: it never ran one here, `make kitti` runs on
    the repository's committed toy figures)."""
    root = protocol.root
    assert json.loads((root / "metrics/generalization.json").read_text()) == {}
    record = json.loads((root / "records/generalization.json").read_text())
    assert record["worlds"] == 0 and "no world" in record["not_run"]
    assert (root / "report/generalization.png").read_bytes()[:4] == b"\x89PNG"
    assert (root / "plots/generalization.csv").read_text().startswith("world,")


def _write_summary(folder: Path, summary: dict[str, Any]) -> Path:
    """``summary`` as folder/metrics/NAME.json and folder/records/NAME.json (kitti-table's
    input, as `make kitti` copies it); the metrics path."""
    from pipeline.outputs import write_metrics
    from pipeline.report.metrics import RECORD_KEYS

    path = folder / "metrics" / "other.json"
    write_metrics(path, folder / "records" / "other.json", summary, RECORD_KEYS)
    return path


def test_table2_lays_out_every_algorithm(protocol: Protocol, tmp_path: Path) -> None:
    metrics = protocol.root / "metrics/evaluation.json"
    m = read_summary(metrics)
    other = _write_summary(tmp_path, {**m, "algorithm": "other"})
    code = CliRunner().invoke(main, ["kitti-table", str(metrics),
                                     str(other), "--out", str(tmp_path / "t")]).exit_code
    assert code == 0
    md = (tmp_path / "t/table.md").read_text().splitlines()
    head = next(line for line in md if line.startswith("| algorithm"))
    assert head == ("| algorithm | setting | 01 | 04 | training avg | 06 | 10 | test avg |")
    assert [line.split("|")[1:3] for line in md if line.split("|")[2:3] == [" baseline "]] == [
        [" kiss_icp ", " baseline "], [" other ", " baseline "]]
    table = json.loads((tmp_path / "t/table.json").read_text())
    kiss = table["algorithms"]["kiss_icp"]
    assert kiss["averages"]["train"]["t_err_pct"]["fixed"] == pytest.approx(
        m["splits"]["train"]["kitti"]["fixed"]["t_err_pct"])
    assert kiss["sequences"]["06"]["t_err_pct"]["adaptive"] == pytest.approx(
        m["sequences"]["06"]["kitti"]["adaptive"]["t_err_pct"])
    # --replicas 1: two runs of every setting, the nominal one first, their spread in the table
    reps = m["splits"]["validation"]["replicas"]["adaptive"]["kitti_t_err_pct"]
    assert reps[0] == m["splits"]["validation"]["kitti"]["adaptive"]["t_err_pct"]
    assert kiss["replicas"]["validation"]["adaptive"] == reps and len(reps) == 2
    spread = next(line for line in md if line.startswith("| kiss_icp | 2 | baseline |"))
    lo, hi = sorted(m["splits"]["train"]["replicas"]["baseline"]["kitti_t_err_pct"])
    assert f"{(lo + hi) / 2:.3f} [{lo:.3f}, {hi:.3f}]" in spread.split("|")[4]
    # blocks of different protocols do not share a table
    _write_summary(tmp_path, {**m, "algorithm": "other", "length_m": 100.0})
    result = CliRunner().invoke(main, ["kitti-table", str(metrics),
                                       str(other), "--out", str(tmp_path / "u")])
    assert result.exit_code == 1
    assert result.output.strip() == (f"adaptune: error: metrics of 'other': L = 100.0 m, the "
                                     f"others {KITTI_L_M} m")
    assert not (tmp_path / "u").exists()


def test_a_second_run_gives_the_same_numbers(protocol: Protocol, tmp_path: Path) -> None:
    """Determinism (issue 15): the SMBO studies of the protocol (trials and the joint study,
    the stages with parallel workers and a search that reacts to what it was told; here on the
    Dask cluster) run again from scratch in a copy of the project (`dvc repro -f -s`) give the
    same trials tables, but the wall times, and the same trajectory of every trial. The stages
    after them are deterministic given their inputs (tests/test_adaptive_evaluate.py: any
    number of workers gives the same results); `dvc metrics diff` shows no wall time
    (test_pipeline_dvc.py)."""
    import pyarrow.parquet as pq

    first, again = protocol.root, tmp_path / "again"
    shutil.copytree(first, again, symlinks=True)
    git(again, "add", "-A")
    git(again, "commit", "-qm", "the first run")
    log = dvc(again, "repro", "-f", "-s", "trials", "fixed")
    for stage in ("trials", "fixed"):
        assert f"Running stage '{stage}'" in log
    assert "Running stage 'evaluate'" not in log
    tables = sorted(p.relative_to(first) for p in first.glob("results/*/**/*.parquet")
                    if p.relative_to(first).parts[1] in ("trials", "fixed"))
    assert sorted(p.relative_to(again) for p in again.glob("results/*/**/*.parquet")
                  if p.relative_to(again).parts[1] in ("trials", "fixed")) == tables
    assert any(p.name == "trials.parquet" for p in tables)
    assert any(p.parts[1] == "fixed" for p in tables)
    for path in tables:
        a, b = (pq.read_table(root / path) for root in (first, again))
        keep = [c for c in a.column_names if c != "wall_time_s"]
        assert b.select(keep).equals(a.select(keep)), path


def overrides(out: str, tmp_path: Path) -> dict[str, Any]:
    """params.yaml after the preset's ``--set-param``s, applied as `dvc exp run` applies them
    (DVC's Hydra overrides), to a params.yaml with a stale window of sequence 99."""
    from dvc.utils.hydra import apply_overrides

    params = yaml.safe_load((REPO / "params.yaml").read_text())
    params["simulate_kitti"]["windows"] = [["99", 0, 9]]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    apply_overrides(tmp_path / "params.yaml",
                    [line.removeprefix("--set-param=") for line in out.splitlines()])
    return yaml.safe_load((tmp_path / "params.yaml").read_text())


def test_preset_of_simulated_kitti(kitti_trajectories: Path, tmp_path: Path) -> None:
    from pipeline.sim.kitti_dataset import SimulateKittiSection

    code, out = _preset("--simulated", str(kitti_trajectories), "--change-windows", "250",
                        "--window", "06=0:99", "--params", str(REPO / "params.yaml"))
    assert code == 0
    params = overrides(out, tmp_path)
    assert params["base"]["sequences"] == "data/kitti_sim"
    assert params["simulate_kitti"]["train"] == ["00", "01", "02", "03", "04", "05"]
    # as the stage reads it; the stale window is gone
    windows = {n: (a, b) for n, a, b in
               SimulateKittiSection.model_validate(params["simulate_kitti"]).windows}
    assert set(windows) == {f"{i:02d}" for i in range(11)}
    assert windows["05"] == (600, 849)  # residential -> urban at 700
    assert windows["04"] == (0, 249) and windows["06"] == (0, 99)
    code, out = _preset("--root", str(kitti_trajectories), "--window", "06=0:99")
    assert code == 1 and "windows of single sequences need the simulated source" in out


def test_preset_stride_and_bad_input(kitti_root: Path) -> None:
    code, out = _preset("--root", str(kitti_root), "--train", "01,04", "--test", "06,10",
                        "--stride", "2", "--params", str(REPO / "params.yaml"))
    assert code == 0
    root = json.dumps(str(kitti_root.resolve()))
    assert (f'--set-param=data.sources=[{{kind:"kitti",path:{root},sequences:["01"],'
            f'split:"train"}},{{kind:"kitti",path:{root},sequences:["06"],'
            f'split:"validation"}}]') in out.splitlines()
    assert "trials.time_limit_s" not in out  # params.yaml's, unless asked
    assert "trials.fidelity" not in out
    code, out = _preset("--root", str(kitti_root), "--train", "01", "--test", "06",
                        "--time-limit-s", "60", "--params", str(REPO / "params.yaml"))
    assert code == 0 and "--set-param=trials.time_limit_s=60.0" in out.splitlines()
    code, out = _preset("--root", str(kitti_root), "--train", "01", "--test", "06",
                        "--time-limit-s", "0")
    assert (code, out) == (1, "adaptune: error: kitti-preset.time_limit_s: Input should be "
                                 "greater than 0, got 0.0\n")
    code, out = _preset("--root", str(kitti_root), "--train", "01", "--test", "06",
                        "--fidelity", "halving", "--params", str(REPO / "params.yaml"))
    assert code == 0
    assert {'--set-param=trials.fidelity="halving"',
            '--set-param=fixed.fidelity="halving"'} <= set(out.splitlines())
    code, out = _preset("--root", str(kitti_root), "--train", "01", "--test", "06",
                        "--replicas", "-1")
    assert (code, out) == (1, "adaptune: error: kitti-preset.replicas: Input should be "
                                 "greater than or equal to 0, got -1\n")
    code, out = _preset("--root", str(kitti_root), "--params", str(REPO / "params.yaml"))
    assert code == 1 and out.count("\n") == 1
    assert out.startswith(f"adaptune: error: root: {kitti_root / 'sequences' / '00'} does not "
                          "exist (sequences 00, 02, 03, 05, 07, 08, 09 missing)")
    code, out = _preset("--root", str(kitti_root), "--train", "01", "--test", "01")
    assert code == 1
    assert out == ("adaptune: error: kitti-preset: sequence '01' is in both train and test, "
                   "got (train=['01'], test=['01'])\n")
