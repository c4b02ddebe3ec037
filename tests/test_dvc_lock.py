"""The committed dvc.lock files are what main's code computes (docs/design.md, "Same numbers on
every machine"): in a fresh clone `dvc status` finds no stage whose code, params or command
changed since its lock was written, only outputs that are not there yet. A change to a stage's
code or params therefore lands with the `dvc repro` that re-ran it, its lock, metrics and docs.

Data dependencies that another stage writes are left to that stage's outputs (a developer's
checkout may hold outputs of an older run); the stages' own code and params are not.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
DVC = Path(sys.executable).with_name("dvc")
PIPELINES = {"dvc.yaml": False, "verdict/dvc.yaml": False, "real/dvc.yaml": True}
"""Each pipeline, and whether a stage that has not run yet (none in its lock) is left out:
the real-data study runs on recordings beside the clone, part by part (its stages that ran
must be current; the others wait for `make real`)."""


def stage_outputs(dvc_yaml: Path) -> set[str]:
    """Every output path of the pipeline's stages (``foreach`` stages: their pattern's prefix
    up to the first ``${``), relative to its folder."""
    paths: set[str] = set()
    for spec in yaml.safe_load(dvc_yaml.read_text())["stages"].values():
        spec = spec.get("do", spec)
        for key in ("outs", "metrics", "plots"):
            for out in spec.get(key) or []:
                path = next(iter(out)) if isinstance(out, dict) else out
                paths.add(path.split("${")[0])
    return paths


def is_output(path: str, outputs: set[str]) -> bool:
    """Whether ``path`` is a stage's output, lies inside one, or is a folder that holds them
    (``models`` holding ``models/${item}``: in a fresh clone it exists with only its
    ``.gitignore``, so DVC calls it modified, not deleted)."""
    return any(path == o.rstrip("/") or (o.endswith(("/", "_")) and path.startswith(o))
               or path.startswith(o.rstrip("/") + "/") or o.startswith(path + "/")
               for o in outputs if o)


def stale(status: dict[str, Any], outputs: set[str]) -> dict[str, Any]:
    """Per stage, what changed besides outputs: a command, a param, a dependency that is no
    stage's output (code, schemas), or one that is not merely missing."""
    out: dict[str, Any] = {}
    for stage, changes in status.items():
        for change in changes:
            if not isinstance(change, dict):
                out.setdefault(stage, []).append(change)  # "changed checksum", "always changed"
                continue
            if "changed command" in change:
                out.setdefault(stage, []).append("changed command")
            for dep, what in (change.get("changed deps") or {}).items():
                params = isinstance(what, dict)  # a params file: {key: "modified" | "new" ...}
                code = not is_output(dep.removeprefix("../"), outputs) and what != "deleted"
                if params or code:
                    out.setdefault(stage, []).append({dep: what})
    return out


@pytest.mark.parametrize("pipeline", list(PIPELINES))
def test_no_stage_has_changed_code_params_or_command_since_its_lock(pipeline: str) -> None:
    dvc_yaml = REPO / pipeline
    if not dvc_yaml.with_name("dvc.lock").exists():
        pytest.skip(f"{pipeline} has no lock: none of its stages has run yet")
    done = subprocess.run([str(DVC), "status", "--json", dvc_yaml.name], cwd=dvc_yaml.parent,
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "DVC_NO_ANALYTICS": "1"})
    assert done.returncode == 0, done.stderr
    status = json.loads(done.stdout or "{}")
    if PIPELINES[pipeline]:
        ran = yaml.safe_load(dvc_yaml.with_name("dvc.lock").read_text())["stages"]
        status = {stage: changes for stage, changes in status.items()
                  if stage.split(":")[-1] in ran}
    assert stale(status, stage_outputs(dvc_yaml)) == {}, (
        f"{pipeline}: stages whose code, params or command changed since dvc.lock: run "
        "`make repro` (or the verdict's) and commit the lock, metrics and docs with the change")


def test_a_folder_holding_outputs_is_left_to_them_but_code_is_not() -> None:
    """A fresh clone's ``models`` (only its ``.gitignore``, the models not pulled) is not
    stale; a changed source file beside it is."""
    status = {"verdict_id": [{"changed deps": {"models": "modified",
                                               "../pipeline/odometry/ndt.py": "modified"}}]}
    assert stale(status, {"models/", "results/fixed"}) == {
        "verdict_id": [{"../pipeline/odometry/ndt.py": "modified"}]}
