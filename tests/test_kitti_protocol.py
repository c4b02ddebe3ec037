"""The KITTI protocol preset (the paper's Table II) end to end through DVC, on real KITTI scans.

What `make kitti` runs: `adaptune kitti-preset` prints the `dvc exp run --set-param`s, `dvc exp
run` takes them (a git + DVC project), `adaptune kitti-table` lays the metrics out. Here on the
10-frame slices of ../shared/data (01, 04 train; 06, 10 test), 3 + 2 trials, L = 1.5 m (sequence
10's 10 frames run 1.7 m), the stages up to evaluate and generalize, which the protocol runs
without a world (its suite's test is in test_pipeline_dvc.py).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from click.testing import CliRunner
from test_pipeline_dvc import BIN, REPO, dvc, git, project, tiny_params

from pipeline.report.outputs import read_summary
from stages.cli import main

pytestmark = pytest.mark.slow

KITTI_L_M = 1.5
"""L here: sequence 10's first 10 frames run 1.7 m, and a sequence not longer than L has no
RTE score (evaluate refuses it; with the tiny params' 4 m it dropped out of its split)."""


def _preset(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["kitti-preset", *args])
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def protocol(kitti_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A git + DVC project on the tiny params, turned into the KITTI protocol and run as `make
    kitti` runs it: the evaluate and generalize targets (the simulated worlds of the simulate
    stage are not made; the generalize stage runs no world)."""
    p = tiny_params()
    p["descriptors"]["range_bins"] = 10  # the default width here
    # searched ranges from params.yaml, wider than ndt's built-in [1, 10] m: every later stage
    # must take them from the trials output (the baseline runs at 11 m)
    p["trials"]["space"] = {"resolution": {"high": 12.0, "default": 11.0}}
    root = project(tmp_path_factory.mktemp("kitti"), p)
    git(root, "add", "-A")
    git(root, "commit", "-qm", "tiny project")
    args = subprocess.run(
        [str(BIN / "adaptune"), "kitti-preset", "--root", str(kitti_root), "--train", "01,04",
         "--test", "06,10", "--iterations", "3", "--joint-iterations", "2",
         "--length-m", str(KITTI_L_M), "--kitti-lengths-m", "2,4", "--replicas", "1"],
        cwd=root, check=True, capture_output=True, text=True).stdout.splitlines()
    log = dvc(root, "exp", "run", *args, "evaluate", "generalize")
    assert "Running stage 'ingest'" in log and "Running stage 'simulate'" not in log
    assert "Running stage 'generalize'" in log
    return root


def test_the_preset_sets_the_protocol(protocol: Path, kitti_root: Path) -> None:
    params = yaml.safe_load((protocol / "params.yaml").read_text())
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
    lock = yaml.safe_load((protocol / "dvc.lock").read_text())["stages"]
    assert any(d["path"] == "data/recordings" for d in lock["trials"]["deps"])


def test_train_and_test_sequences_are_scored(protocol: Path) -> None:
    from pipeline.evaluate.result import SETTINGS
    from pipeline.sequence import SequenceReader

    for seq in ("01", "04", "06", "10"):
        with SequenceReader(protocol / f"data/recordings/{seq}.mcap") as reader:
            assert len(reader) == 10 and reader.info.sensor != "unknown"
        assert (protocol / f"results/adaptive/{seq}/trajectory.parquet").is_file()
    m = read_summary(protocol / "metrics/evaluation.json")
    assert m["headline_split"] == "validation"
    assert {s: v["sequences"] for s, v in m["splits"].items()} == {
        "validation": ["06", "10"], "train": ["01", "04"]}
    assert {n: s["split"] for n, s in m["sequences"].items()} == {
        "06": "validation", "10": "validation", "01": "train", "04": "train"}
    assert m["rte_pct"] == m["splits"]["validation"]["rte_pct"]
    assert all(0 < v < 50 for v in m["rte_pct"].values())
    assert m["params"]["baseline"]["resolution"] == 11.0
    model = json.loads((protocol / "model/manifest.json").read_text())
    (resolution,) = [s for s in model["parameter_space"] if s["name"] == "resolution"]
    assert (resolution["high"], resolution["default"]) == (12.0, 11.0)
    for split in m["splits"].values():  # the devkit pools the segments of the split
        for s in SETTINGS:
            per = [m["sequences"][n]["kitti"][s] for n in split["sequences"]]
            n = sum(k["segments"] for k in per)
            assert n == split["kitti"][s]["segments"] > 0
            pooled = sum(k["t_err_pct"] * k["segments"] for k in per if k["segments"]) / n
            assert split["kitti"][s]["t_err_pct"] == pytest.approx(pooled, rel=1e-12)
    report = (protocol / "report/report.md").read_text()
    assert "| ndt | baseline |" in report and "## Per split" in report


def test_the_protocol_carries_no_stale_suite(protocol: Path) -> None:
    """The experiment's generalize stage ran no world: its metrics are empty, its record and
    figure say so (not the tiny project's suite: it never ran one here, `make kitti` runs on
    the repository's committed toy figures)."""
    assert json.loads((protocol / "metrics/generalization.json").read_text()) == {}
    record = json.loads((protocol / "records/generalization.json").read_text())
    assert record["worlds"] == 0 and "no world" in record["not_run"]
    assert (protocol / "report/generalization.png").read_bytes()[:4] == b"\x89PNG"
    assert (protocol / "plots/generalization.csv").read_text().startswith("world,")


def _write_summary(folder: Path, summary: dict[str, Any]) -> Path:
    """``summary`` as folder/metrics/NAME.json and folder/records/NAME.json (kitti-table's
    input, as `make kitti` copies it); the metrics path."""
    from pipeline.report.metrics import RECORD_KEYS
    from pipeline.report.outputs import write_metrics

    path = folder / "metrics" / "other.json"
    write_metrics(path, folder / "records" / "other.json", summary, RECORD_KEYS)
    return path


def test_table2_lays_out_every_algorithm(protocol: Path, tmp_path: Path) -> None:
    m = read_summary(protocol / "metrics/evaluation.json")
    other = _write_summary(tmp_path, {**m, "algorithm": "other"})
    code = CliRunner().invoke(main, ["kitti-table", str(protocol / "metrics/evaluation.json"),
                                     str(other), "--out", str(tmp_path / "t")]).exit_code
    assert code == 0
    md = (tmp_path / "t/table.md").read_text().splitlines()
    head = next(line for line in md if line.startswith("| algorithm"))
    assert head == ("| algorithm | setting | 01 | 04 | training avg | 06 | 10 | test avg |")
    assert [line.split("|")[1:3] for line in md if line.split("|")[2:3] == [" baseline "]] == [
        [" ndt ", " baseline "], [" other ", " baseline "]]
    table = json.loads((tmp_path / "t/table.json").read_text())
    ndt = table["algorithms"]["ndt"]
    assert ndt["averages"]["train"]["t_err_pct"]["fixed"] == pytest.approx(
        m["splits"]["train"]["kitti"]["fixed"]["t_err_pct"])
    assert ndt["sequences"]["06"]["t_err_pct"]["adaptive"] == pytest.approx(
        m["sequences"]["06"]["kitti"]["adaptive"]["t_err_pct"])
    # --replicas 1: two runs of every setting, the nominal one first, their spread in the table
    reps = m["splits"]["validation"]["replicas"]["adaptive"]["kitti_t_err_pct"]
    assert reps[0] == m["splits"]["validation"]["kitti"]["adaptive"]["t_err_pct"]
    assert ndt["replicas"]["validation"]["adaptive"] == reps and len(reps) == 2
    spread = next(line for line in md if line.startswith("| ndt | 2 | baseline |"))
    lo, hi = sorted(m["splits"]["train"]["replicas"]["baseline"]["kitti_t_err_pct"])
    assert f"{(lo + hi) / 2:.3f} [{lo:.3f}, {hi:.3f}]" in spread.split("|")[4]
    # blocks of different protocols do not share a table
    _write_summary(tmp_path, {**m, "algorithm": "other", "length_m": 100.0})
    result = CliRunner().invoke(main, ["kitti-table", str(protocol / "metrics/evaluation.json"),
                                       str(other), "--out", str(tmp_path / "u")])
    assert result.exit_code == 1
    assert result.output.strip() == (f"adaptune: error: metrics of 'other': L = 100.0 m, the "
                                     f"others {KITTI_L_M} m")
    assert not (tmp_path / "u").exists()


def test_a_second_run_gives_the_same_numbers(protocol: Path, tmp_path: Path) -> None:
    """Determinism (issue 15): the SMBO studies of the protocol (trials and the joint study,
    the stages with parallel workers and a search that reacts to what it was told) run again
    from scratch in a copy of the project (`dvc repro -f -s`) give the same trials tables, but
    the wall times, and the same trajectory of every trial. The stages after them are
    deterministic given their inputs (tests/test_adaptive_evaluate.py: any number of workers
    gives the same results); `dvc metrics diff` shows no wall time (test_pipeline_dvc.py)."""
    import pyarrow.parquet as pq

    again = tmp_path / "again"
    shutil.copytree(protocol, again, symlinks=True)
    git(again, "add", "-A")
    git(again, "commit", "-qm", "the first run")
    log = dvc(again, "repro", "-f", "-s", "trials", "fixed")
    for stage in ("trials", "fixed"):
        assert f"Running stage '{stage}'" in log
    assert "Running stage 'evaluate'" not in log
    tables = sorted(p.relative_to(protocol) for p in protocol.glob("results/*/**/*.parquet")
                    if p.relative_to(protocol).parts[1] in ("trials", "fixed"))
    assert sorted(p.relative_to(again) for p in again.glob("results/*/**/*.parquet")
                  if p.relative_to(again).parts[1] in ("trials", "fixed")) == tables
    assert any(p.name == "trials.parquet" for p in tables)
    assert any(p.parts[1] == "fixed" for p in tables)
    for path in tables:
        a, b = (pq.read_table(root / path) for root in (protocol, again))
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
