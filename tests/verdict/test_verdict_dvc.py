"""The coverage pipeline (verdict/dvc.yaml) through DVC itself, on a tiny params file, beside
the toy pipeline in a temporary git repository: every stage runs, the metrics follow their
shape, a second `dvc repro` does nothing, and a dev suite is one `dvc exp run -S` away."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent

pytestmark = pytest.mark.slow


def tiny_params() -> dict[str, Any]:
    """verdict/params.yaml with three short training sequences, a few trials, two tiny
    tuning worlds, two tiny in-distribution worlds, one out-of-distribution world and a 2 x 1
    oracle and portfolio grid; the VLP-16 everywhere (the fastest sensor to simulate: the
    suites' sensors are params like the rest)."""
    p = yaml.safe_load((REPO / "verdict" / "params.yaml").read_text())
    p["base"]["length_m"] = 4.0
    p["simulate"].update(train={"cave": 1, "open": 1, "street": 1}, train_frames=40,
                         train_sensors=["vlp16"], workers=1)  # in the stage's process
    p["descriptors"].update(workers=1, pca_dim=4, range_bins=3)
    p["trials"].update(iterations=3, workers=1, startup_trials=2)
    p["fixed"].update(iterations=2, warm_start=1)
    p["surrogate"].update(k=20, cv_max_frames=10)  # k below the tiny tables' rows
    p["portfolio"]["grid"] = {"resolution": [2.0, 6.0], "keyframe_interval": [4.0]}
    v = p["verdict"]
    v["suites"]["id"].update(worlds=2, segments=[2, 2], frames=[60, 60], sensors=["vlp16"])
    v["suites"]["ood"].update(worlds=1, segments=[2, 2], frames=[60, 60])
    v.update(fixed_trials=2, fixed_warm_start=1, replicas=1, resamples=200, workers=2,
             borrow_model=None,  # the only trained sensor here is the VLP-16
             tuning={"seed_root": v["tuning"]["seed_root"], "worlds": 2},
             oracle={"resolution": [2.0, 6.0], "keyframe_interval": [4.0]})
    return p


def run(cwd: Path, *args: str) -> str:
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run(list(args), cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=1800)
    assert done.returncode == 0, f"{' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A git + DVC project with both pipelines and the tiny verdict params, the coverage
    pipeline reproduced and committed."""
    root = tmp_path_factory.mktemp("verdict")
    for name in ("dvc.yaml", "params.yaml", ".dvcignore", ".gitignore"):
        shutil.copy(REPO / name, root / name)
    for code in ("pipeline", "schemas", "stages", "studies"):
        (root / code).symlink_to(REPO / code, target_is_directory=True)
    (root / "verdict").mkdir()
    shutil.copy(REPO / "verdict" / "dvc.yaml", root / "verdict" / "dvc.yaml")
    (root / "verdict" / "params.yaml").write_text(yaml.safe_dump(tiny_params(), sort_keys=False))
    dvc = str(BIN / "dvc")
    run(root, "git", "init", "-q", "-b", "main")
    run(root, "git", "config", "user.name", "adaptune tests")
    run(root, "git", "config", "user.email", "tests@adaptune.invalid")
    run(root, dvc, "init", "-q")
    run(root, dvc, "config", "cache.type", "hardlink,symlink")
    log = run(root, dvc, "repro", "verdict/dvc.yaml")
    run(root, "git", "add", "-A")
    run(root, "git", "commit", "-q", "-m", "tiny verdict")
    return root, log


def test_every_stage_ran_and_wrote_its_metrics(project: tuple[Path, str]) -> None:
    root, log = project
    stages = yaml.safe_load((root / "verdict" / "dvc.yaml").read_text())["stages"]
    for name, spec in stages.items():  # a foreach stage runs once per trained sensor
        for stage in [f"{name}@vlp16"] if "foreach" in spec else [name]:
            assert f"Running stage 'verdict/dvc.yaml:{stage}'" in log
    assert (root / "verdict" / "models" / "vlp16" / "manifest.json").is_file()
    assert "Running stage 'evaluate'" not in log  # the toy pipeline is another one
    metrics = root / "verdict" / "metrics"
    for family, worlds in (("id", 2), ("ood", 1)):
        m = json.loads((metrics / f"{family}.json").read_text())
        assert (m["family"], m["suite"], m["worlds"], m["replicas"]) == (family, "test",
                                                                         worlds, 1)
        assert list(m["per_world"]) == [f"{family}_test_{i:02d}" for i in range(worlds)]
        assert set(m["ratios"]) == {"adaptive_vs_fixed", "adaptive_vs_baseline",
                                    "adaptive_vs_best", "fixed_vs_baseline"}
        assert all(len(w["runs_rte_pct"]["adaptive"]) == 2 for w in m["per_world"].values())
        assert m["pooled"]["fixed"]["sub_trajectories"] > 0
        assert (root / "verdict" / "report" / f"{family}.png").stat().st_size > 0
    # the oracles' runs do not depend on the selector: a new one re-scores the headroom alone
    assert not {"models", "results/suites/id"} & set(stages["oracles"]["deps"])
    assert not [p for p in stages["oracles"]["params"] if p.startswith("select.")
                and p != "select.period_s"]
    h = json.loads((metrics / "headroom.json").read_text())
    assert h["worlds"] == 2 and len(h["candidates"]) in (3, 4)  # 2 grid sets, baseline, fixed
    assert set(h["closed_gap"]) == {"oracle", "class_oracle"}
    assert not (root / "verdict" / "results" / "suites" / "id" / "worlds").exists()


def test_second_repro_is_a_no_op(project: tuple[Path, str]) -> None:
    root, _ = project
    out = run(root, str(BIN / "dvc"), "repro", "verdict/dvc.yaml:verdict_id",
              "verdict/dvc.yaml:verdict_ood")
    assert "Running stage" not in out


def test_a_dev_suite_is_one_experiment_away(project: tuple[Path, str]) -> None:
    root, _ = project
    run(root, str(BIN / "dvc"), "exp", "run", "--temp", "-n", "dev",
        "-S", "verdict/params.yaml:verdict.suite=dev", "verdict/dvc.yaml:verdict_ood")
    shown = json.loads(run(root, str(BIN / "dvc"), "exp", "show", "--json"))
    revs = {rev["name"]: rev["data"] for commit in shown
            for exp in commit.get("experiments") or [] for rev in exp["revs"]}
    ood = revs["dev"]["metrics"]["verdict/metrics/ood.json"]["data"]
    assert (ood["suite"], list(ood["per_world"])) == ("dev", ["ood_dev_00"])
