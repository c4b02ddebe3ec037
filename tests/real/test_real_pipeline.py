"""The real-data pipeline (real/dvc.yaml) through DVC on a small slice of two real runs.

hku_1's first 80 keyframes (18 m, hand-held, L = 3 m here) and riverside02's keyframes 100-139
(the drive, L = 20 m here) across its 41 m gap, cut into two pieces by the source's ``pieces``
option: every stage runs (`dvc repro`), the units are the halves by distance with each run's
own L, both in-distribution folds run (hku_1 is the only run left out by the out-of-environment
family, which then has nothing to train on), the report scores every ratio both ways with the
reference's floor, the deploy models load in `adaptune select`, and a second `dvc repro` does
nothing. NDT only, a few trials each: the wiring, not the study's figures.
"""

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

from studies.real.fold import NO_CROSS_VALIDATION

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent

pytestmark = pytest.mark.slow

SLICES = {"hku_1": range(0, 80), "riverside02": range(100, 140)}
"""The frames of each run the test uses (scan files named by frame number: each takes its row
of the run's poses and times files)."""


def tiny_params(slices: Path, real: Path) -> dict[str, Any]:
    """real/params.yaml with the two slices, NDT, a few trials and small statistics."""
    p = yaml.safe_load((REPO / "real" / "params.yaml").read_text())
    sources = {s["name"]: s for s in p["data"]["sources"]}
    for name, source in sources.items():
        for key in ("poses", "times"):
            source[key] = str(real / name / Path(source[key]).name)
        source["path"] = f"../slices/{name}"
    sources["hku_1"]["length_m"] = 3.0
    sources["riverside02"]["length_m"] = 20.0
    p["data"]["sources"] = [sources["hku_1"], sources["riverside02"]]
    runs = {r["name"]: r for r in p["real"]["runs"]}
    for name, run in runs.items():
        run["odometry"] = str(real / name / "odom_poses.txt")
    p["real"].update(algorithms=["ndt"], runs=[runs["hku_1"], runs["riverside02"]],
                     spaces={"ndt": p["real"]["spaces"]["ndt"]},
                     candidates_k=[2, 3], resamples=200, workers=1,
                     failure_pct={3: 20.0, 20: 10.0})
    p["descriptors"].update(workers=1, pca_dim=4, range_bins=3)
    p["trials"].update(iterations=4, workers=1, startup_trials=2)
    p["fixed"].update(iterations=2, warm_start=1)
    p["surrogate"].update(n_sobol=16, cv_max_frames=20)
    return p


def run(cwd: Path, *args: str) -> str:
    """``args`` (a command of the venv) in ``cwd``; stdout and stderr, after asserting that it
    succeeded."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run([str(BIN / args[0]), *args[1:]], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


@pytest.fixture(scope="module")
def repro(real_runs: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The real pipeline on the slices, reproduced once (in ``<root>/real``)."""
    root = tmp_path_factory.mktemp("real_project")
    for name, frames in SLICES.items():
        scans = root / "slices" / name
        scans.mkdir(parents=True)
        for k in frames:
            (scans / f"{k:06d}.pcd").symlink_to(real_runs / name / "scans" / f"{k:06d}.pcd")
    for name in (".dvcignore", ".gitignore"):
        shutil.copy(REPO / name, root / name)
    for code in ("pipeline", "schemas", "stages", "studies"):
        (root / code).symlink_to(REPO / code, target_is_directory=True)
    (root / "real").mkdir()
    text = (REPO / "real" / "dvc.yaml").read_text()
    assert "../../shared/data/real" in text  # the runs, beside the clone
    text = text.replace("../../shared/data/real", "../slices")
    for other in ("gicp", "kiss_icp"):  # the report's deps: NDT's folds alone ran
        assert f" results/{other}/folds," in text
        text = text.replace(f" results/{other}/folds,", "")
    (root / "real" / "dvc.yaml").write_text(text)
    (root / "real" / "params.yaml").write_text(
        yaml.safe_dump(tiny_params(root / "slices", real_runs), sort_keys=False))
    subprocess.run(["git", "init", "-q", "-b", "main"], cwd=root, check=True)
    run(root, "dvc", "init", "-q")
    return root / "real", run(root / "real", "dvc", "repro")


def test_every_stage_ran_and_a_second_repro_does_nothing(repro: tuple[Path, str]) -> None:
    folder, log = repro
    stages = yaml.safe_load((folder / "dvc.yaml").read_text())["stages"]
    for name in ("ingest", "units", "descriptors", "studies@ndt", "folds@ndt", "models@ndt",
                 "report"):
        assert f"Running stage '{name}'" in log
    assert set(stages) == {"ingest", "units", "descriptors", "studies", "folds", "models",
                           "report"}
    assert "Running stage" not in run(folder, "dvc", "repro")


def test_the_drive_is_cut_at_its_gap_and_every_run_has_its_own_length(
        repro: tuple[Path, str]) -> None:
    from pipeline.sequence import SequenceReader

    folder, _ = repro
    recordings = sorted(p.name for p in (folder / "data/recordings").glob("*.mcap"))
    assert recordings == ["hku_1.mcap", "riverside02_p0.mcap", "riverside02_p1.mcap"]
    units = json.loads((folder / "data/units/units.json").read_text())["units"]
    assert [(u["name"], u["half"]) for u in units] == [
        ("hku_1_h1", "h1"), ("hku_1_h2", "h2"), ("riverside02_p0_h1", "h1"),
        ("riverside02_p1_h1", "h1"), ("riverside02_p1_h2", "h2")]
    hku = [u for u in units if u["run"] == "hku_1"]
    assert abs(hku[0]["path_m"] - hku[1]["path_m"]) < 1.0  # halves by distance
    assert sum(u["frames"] for u in hku) == len(SLICES["hku_1"])
    for u in units:
        with SequenceReader(folder / "data/units" / f"{u['name']}.mcap") as reader:
            assert reader.info.length_m == (3.0 if u["run"] == "hku_1" else 20.0)


def test_the_report_gives_every_ratio_both_ways_with_the_floor(repro: tuple[Path, str]) -> None:
    folder, _ = repro
    m = json.loads((folder / "metrics/real.json").read_text())
    runs = m["by_algorithm"]["ndt"]["runs"]
    assert sorted((r["fold"], r["run"]) for r in runs) == [
        ("in_a", "hku_1"), ("in_a", "riverside02"), ("in_b", "hku_1"), ("in_b", "riverside02")]
    for r in runs:
        assert set(r["ratios"]) >= {"fixed_vs_baseline", "adaptive_vs_fixed",
                                    "adaptive_vs_in_sample"}
        for way in ("all", "finished"):
            ratio = r["ratios"]["adaptive_vs_fixed"][way]
            assert ratio["sub_trajectories"] >= 0
        assert r["floor"]["rte_pct"] is not None and r["floor"]["rte_pct"] >= 0
        assert set(r["pooled"]) == {"baseline", "fixed", "adaptive", "in_sample"}
        if r["k_chosen_by"] == "cross-validation":
            assert r["k"] in (2, 3)
        else:  # a fold with fewer than two training units that have a finished trial
            assert r["k_chosen_by"] == NO_CROSS_VALIDATION and r["k"] == 20
    assert set(m["by_algorithm"]["ndt"]["families"]) == {"in_distribution"}
    cost = m["by_algorithm"]["ndt"]["cost"]
    assert cost["unit_studies"]["all"] == 5 * 4
    assert cost["in_a"]["suite_runs"] == 2 * 4 * 4  # test units x settings x (R + 1): hku_1_h2,
    assert m["halves"]["riverside02"]["closest_m"] is not None  # riverside02_p1_h2
    assert (folder.parent / "docs/results/real-topview.png").stat().st_size > 0
    assert set(m["targets"]) == {"tuning_pays", "adapting_pays_in_distribution",
                                 "out_of_environment", "worst_run"}


def test_the_deploy_models_load_in_select(repro: tuple[Path, str], tmp_path: Path) -> None:
    folder, _ = repro
    for sensor, unit in (("livox_avia", "hku_1_h2"), ("os1_64", "riverside02_p1_h2")):
        out = tmp_path / f"{sensor}.csv"
        run(folder, "adaptune", "select", f"models/{sensor}/ndt", f"data/units/{unit}.mcap",
            "--out", str(out), "-a", "ndt")
        assert len(out.read_text().splitlines()) > 1


def test_the_docs_page_renders_from_the_reports_metrics(repro: tuple[Path, str]) -> None:
    from studies.docs.real_page import real_page

    folder, _ = repro
    m = json.loads((folder / "metrics/real.json").read_text())
    page = real_page(m, ["> provenance"], {"real": {"algorithms": ["ndt"]}})
    assert "\n## ndt\n" in page and "> provenance" in page
    assert page.endswith("```yaml\nreal:\n  algorithms: [ndt]\n```\n\n</details>\n")
