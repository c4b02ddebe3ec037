"""The whole pipeline through DVC itself, on a tiny params file, in a temporary git repository.

Every stage of dvc.yaml runs (`dvc repro`, without a warning), every output exists and follows
its schema, and a second `dvc repro` does nothing. Then the variation lines of docs/usage.md for
the simulated worlds run as one DVC experiment on the same project (`dvc exp run -S ...`), and
`dvc exp show` (the documented `--keep` line: at most 120 columns), `dvc exp diff`, `dvc metrics
diff` and `dvc plots diff` compare it with main: the metrics, records and plot data are committed
to git (``cache: false``), as DVC's example-get-started does, and the metrics hold figures only.
The KITTI, kiss_icp and Dask-cluster lines run in tests/test_kitti_protocol.py's experiment (one
KITTI pipeline for the suite). The generalize stage runs its suite in the first `dvc repro`
alone (its test here); the experiments run it with ``generalize.worlds=0`` (no world, outputs
that say so: no stale figure of the first run) and the command adapter's repro stops at the
evaluate stage, to keep the suite short.
"""

from __future__ import annotations

import itertools
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent

pytestmark = pytest.mark.slow

TINY_L_M = 4.0
GENERALIZE_FRAMES = 30
"""Frames of each world of the generalize stage's suite here (two segments of 15)."""
TCP_LINE = "trials.dask=tcp://SCHEDULER:8786,trials.workers=8"
"""docs/usage.md's line for trials on a Dask cluster (its own section)."""


def tiny_params() -> dict[str, Any]:
    """The repository's params.yaml with a few frames, a few trials and a short L."""
    p = yaml.safe_load((REPO / "params.yaml").read_text())
    p["base"]["length_m"] = TINY_L_M
    # the sequences simulated and evaluated in the stage's own process (workers=1), not in two
    # spawned ones that import and compile numba's kernels again: the same files for any workers
    # (tests/sim/test_simulate_set.py, tests/test_adaptive_evaluate.py)
    p["simulate"].update(train={"cave": 1, "street": 1}, train_frames=50, validation_frames=60,
                         workers=1)
    p["evaluate"].update(workers=1)
    p["descriptors"].update(workers=1, pca_dim=4, range_bins=3)  # 27 values: not the default 90
    p["trials"].update(iterations=3, workers=1, startup_trials=2)
    p["fixed"].update(iterations=2)
    p["surrogate"].update(n_sobol=16, cv_max_frames=20)
    # two worlds of the sensors kept out of training, of the fewest frames a world may have
    # (30: the HDL-64E's took 36 s of the stage's 49 at 50), one replica (params.yaml has two)
    p["generalize"].update(worlds=2, segments=[2, 2], segment_frames=[GENERALIZE_FRAMES // 2] * 2,
                           sensors=["vlp16", "hdl64"], bootstrap=200, replicas=1, workers=2)
    return p


def dvc(cwd: Path, *args: str, columns: int | None = None) -> str:
    """``dvc ARGS`` in ``cwd`` (its tables ``columns`` wide, else rich's default); stdout and
    stderr, after asserting that it succeeded."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    if columns is not None:
        env["COLUMNS"] = str(columns)
    done = subprocess.run([str(BIN / "dvc"), *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, f"dvc {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


def git(cwd: Path, *args: str) -> str:
    done = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, f"git {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def project(root: Path, params: dict[str, Any]) -> Path:
    """A git + DVC project in ``root`` with the repository's dvc.yaml, .gitignore, code and
    ``params``, on branch ``main`` (nothing run, nothing committed yet)."""
    for name in ("dvc.yaml", ".dvcignore", ".gitignore"):
        shutil.copy(REPO / name, root / name)
    for code in ("pipeline", "schemas", "stages", "studies"):  # the stages' code dependencies
        (root / code).symlink_to(REPO / code, target_is_directory=True)
    (root / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    git(root, "init", "-q", "-b", "main")
    git(root, "config", "user.name", "adaptune tests")
    git(root, "config", "user.email", "tests@adaptune.invalid")
    dvc(root, "init", "-q")
    dvc(root, "config", "cache.type", "hardlink,symlink")  # experiments check out in no time
    return root


def reproduce(root: Path, params: dict[str, Any]) -> tuple[Path, str]:
    """``project`` in ``root`` with ``params``, reproduced and committed (what `git status`
    shows: nothing)."""
    log = dvc(project(root, params), "repro")
    git(root, "add", "-A")
    git(root, "commit", "-q", "-m", "tiny pipeline")
    return root, log


@pytest.fixture(scope="module")
def repro(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The toy pipeline (simulated worlds), reproduced once."""
    return reproduce(tmp_path_factory.mktemp("project"), tiny_params())


def test_every_stage_ran(repro: tuple[Path, str]) -> None:
    root, log = repro
    stages = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    for name in stages:
        assert f"Running stage '{name}'" in log
    # a clean run warns of nothing (DVC warned "'pipeline/x/__init__.py' is empty" 42 times)
    assert [line for line in log.splitlines() if "WARNING" in line or "Warning" in line] == []
    lock = yaml.safe_load((root / "dvc.lock").read_text())["stages"]
    assert set(lock) == set(stages)
    # the library code a stage runs is one of its dependencies, hashed without __pycache__
    code = {d["path"]: d for d in lock["trials"]["deps"]}["pipeline/odometry"]
    assert code["md5"].endswith(".dir") and code["nfiles"] == len(
        list((REPO / "pipeline/odometry").glob("*.py")))


def test_outputs_follow_their_schemas(repro: tuple[Path, str]) -> None:
    import duckdb

    from pipeline.evaluate.result import SETTINGS
    from pipeline.odometry.base import Schedule
    from pipeline.pca import Pca
    from pipeline.runtime import load_model
    from pipeline.schema_version import check_schema_version
    from pipeline.sequence import SequenceReader
    from pipeline.trajectory import read_trajectory
    from pipeline.tuning.layout import read_trials_tables
    from schemas.arrow import descriptors_schema

    root, _ = repro
    index = json.loads((root / "data/sequences/index.json").read_text())
    assert index == {"train": ["cave_0", "street_0"], "validation": ["composite_0"]}
    for name in index["train"] + index["validation"]:
        with SequenceReader(root / f"data/sequences/{name}.mcap") as reader:
            assert reader.ground_truth() is not None
    import pyarrow.parquet as pq

    desc = pq.read_table(root / "data/descriptors.parquet")
    check_schema_version(desc.schema, "descriptors")
    assert desc.schema.names == descriptors_schema(27).names and desc.num_rows == 160
    assert Pca.load(root / "data/pca").dim == 4
    trials = read_trials_tables(root / "results/trials")
    assert trials.num_rows == 6
    assert set(trials.column("sequence").to_pylist()) == set(index["train"])
    assert read_trials_tables(root / "results/fixed").num_rows == 2
    con = duckdb.connect(str(root / "results/adaptune.duckdb"), read_only=True)
    try:
        counts = {t: con.execute(f"SELECT count(*) FROM {t}").fetchone()[0]  # type: ignore[index]
                  for t in ("sequences", "trials", "rte_frames", "environment", "surrogate_rows")}
    finally:
        con.close()
    assert counts["sequences"] == 3 and counts["trials"] == 8
    assert counts["rte_frames"] > 0 and counts["surrogate_rows"] > 0
    model = load_model(root / "model", expected_algorithm="ndt")
    assert len(model.surrogate.rows_t) == counts["surrogate_rows"]
    # the novelty fallback was decided on the joint study vs each study's defaults trial
    fallback = model.novelty_fallback
    assert fallback["mode"] == "auto" and set(fallback["per_sequence"]) == set(index["train"])
    run = root / "results/adaptive/composite_0"
    schedule = Schedule.read(run / "schedule.parquet")
    assert len(schedule) == 60 and set(schedule.values) == set(model.names)
    assert len(read_trajectory(run / "trajectory.parquet")) == 60
    for setting in ("baseline", "fixed"):
        path = root / f"results/evaluation/composite_0/{setting}.parquet"
        assert len(read_trajectory(path)) == 60
    metrics = json.loads((root / "metrics/evaluation.json").read_text())
    assert set(metrics["rte_pct"]) == set(SETTINGS)
    assert all(v > 0 for v in metrics["rte_pct"].values())
    record = json.loads((root / "records/evaluation.json").read_text())
    assert record["trials"]["trials"]["trials"] == 6 and record["algorithm"] == "ndt"
    assert "cross_validation" not in metrics and "mae" in json.loads(
        (root / "metrics/surrogate.json").read_text())
    for name in ("evaluation", "surrogate", "generalization"):  # figures, nothing else
        leaves = dict(flat_leaves(json.loads((root / f"metrics/{name}.json").read_text())))
        assert leaves and all(isinstance(v, int | float | list) or v is None
                              for v in leaves.values()), name
        assert not [k for k in leaves if "wall_time" in k or k.endswith(("segments", "rows"))]
    report = (root / "report/report.md").read_text()
    for png in ("world_composite_0.png", "schedule_composite_0.png", "rte_composite_0.png",
                "trajectory_composite_0.png", "trials.png"):
        assert f"(figures/{png})" in report
        assert (root / "report" / "figures" / png).read_bytes()[:4] == b"\x89PNG"
    for csv in ("schedule/resolution", "schedule/keyframe_interval", "rte_frames",
                "trajectory_ground_truth", "trajectory_adaptive"):
        lines = (root / f"plots/{csv}.csv").read_text().splitlines()
        assert len(lines) == 61  # header + 60 frames


def test_generalize_scores_every_world_of_the_suite(repro: tuple[Path, str]) -> None:
    """The generalize stage: two unseen worlds (one per unseen sensor), three settings each."""
    from pipeline.odometry.base import Schedule
    from pipeline.outputs import read_summary
    from pipeline.trajectory import read_trajectory
    from studies.generalization.summary import RATIOS

    root, log = repro
    m = read_summary(root / "metrics/generalization.json")
    assert (m["suite"], m["seed_root"], m["worlds"]) == ("test", 90217, 2)
    worlds = m["per_world"]
    assert [w["sensor"] for w in worlds.values()] == ["vlp16", "hdl64"]
    for name, w in worlds.items():
        assert len(w["segments"]) == 2 and w["frames"] == GENERALIZE_FRAMES
        r = w["rte_pct"]
        assert all(v > 0 for v in r.values())
        assert w["ratio"]["adaptive_vs_best"] == pytest.approx(
            r["adaptive"] / min(r["baseline"], r["fixed"]))
        for setting in ("baseline", "fixed", "adaptive"):  # every nominal run's trajectory
            path = root / f"results/generalization/{name}/{setting}.trajectory.parquet"
            assert len(read_trajectory(path)) == GENERALIZE_FRAMES
        assert len(Schedule.read(root / f"results/generalization/{name}/"
                                 "adaptive.schedule.parquet")) == GENERALIZE_FRAMES
        # one replica of every setting (tiny_params), the ratio of the medians of the runs
        runs = {s: [r[s], *w["replicas_rte_pct"][s]] for s in r}
        assert all(len(v) == 2 and all(x > 0 for x in v) for v in runs.values())
        med = {s: float(np.median(v)) for s, v in runs.items()}
        assert w["replica_ratio"]["adaptive_vs_best"] == pytest.approx(
            med["adaptive"] / min(med["baseline"], med["fixed"]))
    assert not list((root / "results/generalization").rglob("*.mcap"))  # scratch removed
    for ratio in RATIOS:
        s = m["summary"][ratio]
        lo, hi = s["median_interval"]
        assert lo <= s["median"] <= hi and s["worst_world"] in worlds
        assert s["worst"] == max(w["ratio"][ratio] for w in worlds.values())
        assert m["replica_summary"][ratio]["worst"] == max(
            w["replica_ratio"][ratio] for w in worlds.values())
    assert m["replicas"] == 1 and m["noise"]["chance_ratio_p95"] >= 1.0
    assert isinstance(m["summary"]["adaptive_vs_best"]["targets_met"], bool)  # the verdict
    rows = (root / "plots/generalization.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("world,segments,sensor,frames,")
    assert rows[0].endswith(",replica_adaptive_vs_best")
    assert (root / "report/generalization.png").read_bytes()[:4] == b"\x89PNG"
    assert "on the test suite (2 worlds)" in log


def test_second_repro_is_a_no_op(repro: tuple[Path, str]) -> None:
    root, _ = repro
    log = dvc(root, "repro")
    assert "Running stage" not in log
    assert "up to date" in dvc(root, "status")


def test_base_length_makes_the_stages_that_read_it_stale(repro: tuple[Path, str]) -> None:
    """L is one real parameter: changing base.length_m makes exactly its readers stale."""
    root, _ = repro
    path = root / "params.yaml"
    original = path.read_text()
    params = yaml.safe_load(original)
    params["base"]["length_m"] = TINY_L_M + 1
    try:
        path.write_text(yaml.safe_dump(params, sort_keys=False))
        status = json.loads(dvc(root, "status", "--json"))
    finally:
        path.write_text(original)
    changed = {stage: change["changed deps"]["params.yaml"] for stage, changes in status.items()
               for change in changes if "params.yaml" in change.get("changed deps", {})}
    assert changed == {stage: {"base.length_m": "modified"}
                       for stage in ("ingest", "trials", "fixed", "rte", "evaluate",
                                     "generalize")}  # ingest: a piece not longer than L is dropped


def test_metrics_and_plots_commands_read_the_outputs(repro: tuple[Path, str]) -> None:
    root, _ = repro
    shown = json.loads(dvc(root, "metrics", "show", "--json"))
    metrics = next(iter(shown.values()))["data"]
    assert "rte_pct" in metrics["metrics/evaluation.json"]["data"]
    out = dvc(root, "plots", "show", "-o", "dvc_plots")
    assert "dvc_plots" in out
    html = (root / "dvc_plots" / "index.html").read_text()
    for shown in ("plots/schedule/resolution.csv", "plots/schedule/keyframe_interval.csv",
                  "Per-start-frame RTE [%]", "Trajectories (top view)"):
        assert shown in html, shown
    assert "Unseen worlds, adaptive / min(baseline, fixed)" in html
    assert len(list((root / "dvc_plots" / "static").glob("*.png"))) == 6


def test_metrics_and_plot_data_are_committed(repro: tuple[Path, str]) -> None:
    """metrics/, records/ and plots/ are in git, not ignored, not in the DVC cache: nothing left
    over."""
    root, _ = repro
    tracked = git(root, "ls-files", "metrics", "records", "plots").split()
    assert {"metrics/evaluation.json", "metrics/surrogate.json", "plots/rte_frames.csv",
            "plots/schedule/resolution.csv", "records/evaluation.json",
            "records/generalization.json", "records/surrogate.json"} <= set(tracked)
    assert git(root, "status", "--porcelain") == ""


PAPER_SELECTOR = "surrogate.k=5,select.window=1"


DOCUMENTED = ("README.md", "docs/usage.md")
"""The pages whose `dvc exp run` lines are run here (docs/usage.md, "The pipeline under DVC",
is their home; a line added to the README would be run too)."""


ELSEWHERE = "<!-- set-param forms -->\n"
"""The marker of docs/usage.md's `dvc exp run -S` forms of an `adaptune init` project, which
tests/test_project_dvc.py runs on one (not experiments of this pipeline)."""


def documented_variations() -> dict[str, list[str]]:
    """The `dvc exp run` lines (in every ``sh`` block but the one marked ELSEWHERE) of the
    DOCUMENTED pages, keyed by what they set."""
    blocks = [b.split("```", 1)[0] for page in DOCUMENTED
              for before, b in itertools.pairwise((REPO / page).read_text().split("```sh"))
              if not before.endswith(ELSEWHERE)]
    lines = {}
    for line in "\n".join(blocks).replace("\\\n", " ").splitlines():
        if not line.startswith("dvc exp run "):
            continue
        words = shlex.split(line, comments=True)
        if words[:3] == ["dvc", "exp", "run"]:
            sets = dict(w.split("=", 1) for w in words[4::2])
            assert words[3::2] == ["-S"] * len(sets), line
            key = "kitti" if "kind: kitti" in sets.get("data.sources", "") else ",".join(
                f"{k}={v}" for k, v in sets.items())
            lines[key] = words[3:]
    return lines


def tiny(args: list[str], **values: str) -> list[str]:
    """A variation line's ``-S key=value`` arguments with the values of ``values`` replaced."""
    out = []
    for word in args:
        key, _, _ = word.partition("=")
        out.append(f"{key}={values[key]}" if key in values else word)
    return out


SKIP_SUITE = ["-S", "generalize.worlds=0"]
"""The experiments' generalize stage runs no world (docs/usage.md): their metrics say so."""


def exp_run(root: Path, name: str, *args: str) -> str:
    """``dvc exp run --temp -n NAME ARGS -S generalize.worlds=0 evaluate generalize``: the
    stages up to evaluate, and generalize without a world, in a temporary copy."""
    return dvc(root, "exp", "run", "--temp", "-n", name, *args, *SKIP_SUITE, "evaluate",
               "generalize")


def flat_leaves(node: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """The leaves of a parsed JSON as (dotted key, value), as DVC flattens metrics."""
    if isinstance(node, dict):
        return [leaf for k, v in node.items()
                for leaf in flat_leaves(v, f"{prefix}.{k}" if prefix else str(k))]
    return [(prefix, node)]


def exp_shown(root: Path) -> dict[str, dict[str, Any]]:
    """``dvc exp show --json``: the metrics and params files of every experiment, by name."""
    shown = json.loads(dvc(root, "exp", "show", "--json"))
    return {rev["name"]: rev["data"] for commit in shown
            for exp in commit.get("experiments") or [] for rev in exp["revs"]}


def test_documented_variations_are_the_ones_tested() -> None:
    """Every documented line runs: the gicp, local Dask and paper-selector lines here
    (gicp_dask), the KITTI, kiss_icp and cluster lines in tests/test_kitti_protocol.py."""
    assert set(documented_variations()) == {"trials.algorithm=gicp", "trials.algorithm=kiss_icp",
                                        "trials.dask=local", "kitti", TCP_LINE, PAPER_SELECTOR}


GICP_COARSE = "+trials.space.downsampling_resolution={low: 0.8, high: 2.0, default: 1.0}"
"""GICP's clouds downsampled at 0.8-2 m in the test (its own range, 0.1-2 m, default 0.25 m,
makes a trial up to 30x dearer): what the experiment checks does not depend on it."""


@pytest.fixture(scope="module")
def gicp_dask(repro: tuple[Path, str]) -> Path:
    """The documented gicp, Dask and paper-selector lines as one experiment ``gicp-dask`` (to
    keep the suite short) on the reproduced project, GICP on coarse clouds (GICP_COARSE), in a
    temporary copy; the project's root."""
    root, _ = repro
    lines = documented_variations()
    exp_run(root, "gicp-dask", *lines["trials.algorithm=gicp"], *lines["trials.dask=local"],
            *lines[PAPER_SELECTOR], "-S", GICP_COARSE)
    return root


def test_gicp_on_dask_experiment(gicp_dask: Path) -> None:
    """`dvc exp show` sees the experiment's metrics and params, the workspace stays as
    committed."""
    root = gicp_dask
    shown = exp_shown(root)["gicp-dask"]
    metrics = shown["metrics"]["metrics/evaluation.json"]["data"]
    params = shown["params"]["params.yaml"]["data"]
    assert (params["surrogate"]["k"], params["select"]["window"]) == (5, 1)
    assert params["trials"]["algorithm"] == "gicp" and params["base"]["length_m"] == TINY_L_M
    assert params["trials"]["space"]["downsampling_resolution"]["default"] == 1.0
    assert all(0 < v < 100 for v in metrics["rte_pct"].values()), metrics
    # no world was run: no figure of the first run's suite rides along
    assert shown["metrics"]["metrics/generalization.json"]["data"] == {}
    assert git(root, "status", "--porcelain") == ""


def test_diff_commands_compare_the_experiment_with_main(gicp_dask: Path) -> None:
    """`dvc metrics diff`, `dvc plots diff` and `dvc exp diff` of main and the experiment: the
    metrics are figures only (no wall time, no name, no L, among all of them), the first run's
    suite is gone from the experiment's, and every plot of both revisions loads (the suite's
    figure of the experiment says it was not run; before, the stale one failed to load)."""
    root = gicp_dask
    diff = json.loads(dvc(root, "metrics", "diff", "main", "gicp-dask", "--all", "--json"))
    rows = {f"{path}:{key}": row for path, keys in diff.items() for key, row in keys.items()}
    assert "metrics/evaluation.json:rte_pct.adaptive" in rows
    assert not [k for k in rows if "wall_time" in k or "algorithm" in k or "length_m" in k]
    assert rows["metrics/generalization.json:summary.adaptive_vs_best.median"]["new"] is None
    plots = json.loads(dvc(root, "plots", "diff", "main", "gicp-dask", "--json"))
    assert not plots.get("errors"), plots.get("errors")
    diff = json.loads(dvc(root, "exp", "diff", "main", "gicp-dask", "--json"))
    assert diff["params"]["params.yaml"]["trials.algorithm"] == {"old": "ndt", "new": "gicp"}
    assert {f"rte_pct.{s}" for s in ("baseline", "fixed", "adaptive")} <= set(
        diff["metrics"]["metrics/evaluation.json"])


EXP_SHOW_WIDTH = 120


def documented_exp_show() -> list[str]:
    """The arguments of the `dvc exp show` line of docs/usage.md's ``sh`` blocks."""
    blocks = [b.split("```", 1)[0] for b in (REPO / "docs/usage.md").read_text().split("```sh")[1:]]
    (line,) = [ln for b in blocks for ln in b.replace("\\\n", " ").splitlines()
               if ln.startswith("dvc exp show ")]
    return shlex.split(line, comments=True)[3:]


def test_the_documented_exp_show_fits_in_120_columns(gicp_dask: Path) -> None:
    """docs/usage.md's `dvc exp show --keep ...` line, given all the room it wants: every line
    of its table is at most 120 columns, and it shows its columns whole (no "…") for the
    workspace, main and the experiment above (the table had 593 columns)."""
    root = gicp_dask
    args = documented_exp_show()
    assert "--keep" in args and "--drop" in args
    table = dvc(root, "exp", "show", "--no-pager", *args, columns=1000)
    lines = table.rstrip("\n").splitlines()
    assert max(len(line) for line in lines) <= EXP_SHOW_WIDTH, "\n" + table
    assert "…" not in table
    header = next(line for line in lines if "Experiment" in line).split()
    assert header == ["Experiment", "rte_pct.baseline", "rte_pct.fixed", "rte_pct.adaptive",
                      "summary.adaptive_vs_best.median"]
    rows = [line.split() for line in lines[3:-1]]  # rule, header, rule ... rule
    assert [r[0] for r in rows[:2]] == ["workspace", "main"], table
    assert [r[2] for r in rows[2:]] == ["[gicp-dask]"], table  # ├── rev [name]
    for row in rows[2:]:  # the experiment ran no world: no figure of main's suite
        assert row[-1] == "-", table
