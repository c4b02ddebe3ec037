"""An `adaptune init` project under real DVC (issue 57.6): its outputs are git-ignored before
any stage runs, the documented `dvc exp run -S` forms work (the ingest stage only, forced:
every stage loads and checks the whole params.yaml first), options another adapter left are
refused in one line, and `dvc exp show` stays within 40 columns."""

from __future__ import annotations

import csv
import io
import os
import shlex
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner
from helpers.source_inputs import load_kitti, write_bag

from stages.cli import main

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
USAGE = REPO / "docs" / "usage.md"
MAX_COLUMNS = 40


def run(cwd: Path, *args: str, ok: bool = True) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run(list(args), cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)
    if ok:
        assert done.returncode == 0, f"{' '.join(args)}:\n{done.stdout}\n{done.stderr}"
    return done


def documented_lines(marker: str) -> list[list[str]]:
    """The command lines of the sh block after ``<!-- marker -->`` in docs/usage.md."""
    block = USAGE.read_text().split(f"<!-- {marker} -->\n```sh\n", 1)[1].split("```", 1)[0]
    return [shlex.split(ln, comments=True) for ln in block.replace("\\\n", " ").splitlines()
            if ln.strip()]


def columns(project: Path) -> list[str]:
    out = run(project, "dvc", "exp", "show", "--csv").stdout
    return next(csv.reader(io.StringIO(out)))


@pytest.fixture(scope="module")
def project(kitti_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`adaptune init` on two tiny ROS 2 bags (3 KITTI 04 scans each), a git + DVC repository
    with that one commit."""
    root = tmp_path_factory.mktemp("dvcproject")
    kf = load_kitti(kitti_root, "04", 3)
    kf = replace(kf, points=[p[::50].copy() for p in kf.points])
    write_bag(root / "drive1", kf, ros=2, storage="sqlite3", gt="odom")
    write_bag(root / "drive2", kf, ros=2, storage="mcap", gt="pose")
    project = root / "project"
    result = CliRunner().invoke(main, ["init", str(project), "-r", str(root / "drive1"),
                                       "-r", str(root / "drive2"), "--length", "1"])
    assert result.exit_code == 0, result.output
    return project


def test_outputs_are_ignored_before_any_stage_runs(project: Path) -> None:
    """The cached outputs are git-ignored as DVC ignores them, the committed ones (metrics,
    records, plot data) are not; when the ingest stage runs, DVC finds its entry there."""
    from pipeline.project import cached_outputs

    stages = yaml.safe_load((project / "dvc.yaml").read_text())["stages"]
    outs = cached_outputs(stages)
    assert {"data/recordings", "model", "results/trials", "report/report.md"} <= set(outs)
    before = {p: p.read_bytes() for p in project.rglob(".gitignore")}
    assert (project / "data" / ".gitignore").read_text() == (
        "/recordings\n/descriptors.parquet\n/environment.parquet\n/pca\n")
    run(project, "git", "init", "-q", "-b", "main")
    run(project, "dvc", "init", "-q")
    for out in outs:
        assert run(project, "git", "check-ignore", "-q", out, ok=False).returncode == 0, out
    for kept in ("metrics/evaluation.json", "records/surrogate.json", "plots/rte_frames.csv",
                 "params.yaml", "dvc.yaml"):
        assert run(project, "git", "check-ignore", "-q", kept, ok=False).returncode == 1, kept
    run(project, "git", "add", "-A")
    run(project, "git", "commit", "-q", "-m", "adaptune init")
    assert len(columns(project)) <= MAX_COLUMNS
    run(project, "dvc", "repro", "ingest")
    after = {p: p.read_bytes() for p in project.rglob(".gitignore") if ".dvc" not in p.parts}
    assert after == before  # DVC found every entry it writes there already
    status = run(project, "git", "status", "--porcelain").stdout.splitlines()
    # data/recordings: ignored; the ingest stage's record (cache: false) is committed
    assert status == ["?? dvc.lock", "?? records/"], status
    run(project, "git", "add", "dvc.lock", "records")
    run(project, "git", "commit", "-q", "-m", "ingest")


def test_the_documented_set_param_forms(project: Path) -> None:
    """docs/usage.md's `dvc exp run -S` lines run as written (of the ingest stage): keys the
    file lists, ++ for those it does not, ~ to drop the command adapter's options once they
    were committed; without ~ the options left are refused in one line naming them."""
    if not (project / ".dvc").is_dir():
        pytest.skip("needs test_outputs_are_ignored_before_any_stage_runs's repository")
    runs = documented_lines("set-param forms")
    assert len(runs) == 4 and all(ln[:3] == ["dvc", "exp", "run"] for ln in runs)

    def params() -> dict:
        return yaml.safe_load((project / "params.yaml").read_text())

    for args in runs[:3]:
        run(project, *args, "--force", "ingest")  # the stage loads (checks) params.yaml
        got = params()
        if "trials.iterations=32" in args:
            assert got["trials"]["iterations"] == 32 and got["surrogate"]["k"] == 5
            run(project, "git", "checkout", "-q", "--", "params.yaml")  # from the commit
        if "trials.algorithm=command" in args:
            assert got["trials"]["algorithm"] == "command"
            assert got["trials"]["adapter_options"] == {
                "command": "./my_odometry {scans} {params} {out}", "space": "my_space.yaml",
                "scans": "kitti"}
            run(project, "git", "commit", "-q", "-am", "the command adapter")
        if "++trials.pruning.percentile=50" in args:
            assert got["trials"]["pruning"] == {"percentile": 50}
            run(project, "git", "checkout", "-q", "--", "params.yaml")
    refused = run(project, "dvc", "exp", "run", "-S", "trials.algorithm=kiss_icp", "--force",
                  "ingest", ok=False)
    assert refused.returncode != 0
    assert ("adaptune: error: trials.adapter_options: command, scans, space are not options "
            "of kiss_icp") in refused.stdout + refused.stderr
    run(project, "git", "checkout", "-q", "--", "params.yaml")
    run(project, *runs[3], "--force", "ingest")
    assert params()["trials"] == {"algorithm": "kiss_icp", "iterations": 256, "workers": 2}
    assert len(columns(project)) <= MAX_COLUMNS
