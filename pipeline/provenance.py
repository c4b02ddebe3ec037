"""Where an artifact came from: what its inputs held, and the git and DVC state it was made in.

Two kinds, kept apart (docs/design.md, "Same numbers on every machine"): ``content`` is a pure
function of the inputs (their SHA-256), so it goes into the artifact, a cached output whose
bytes the code, params and data alone decide; ``revision`` (git commit, dirty flag, the md5 of
dvc.lock at the time) changes with every commit and run, so it goes into the stage's record.
"""

from __future__ import annotations

import hashlib
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any


def content(inputs: Mapping[str, str]) -> dict[str, Any]:
    """``inputs`` (name -> path) and the SHA-256 of each (a folder: of its files)."""
    from pipeline.file_digest import sha256_tree

    return {"inputs": dict(inputs),
            "inputs_sha256": {name: sha256_tree(path) for name, path in inputs.items()}}


def revision(repo: str | Path | None, inputs: Mapping[str, str]) -> dict[str, Any]:
    """git revision (``git rev-parse HEAD``, dirty flag) and DVC info (md5 of the inputs from
    dvc.lock where present) of the repository ``repo`` (default: the working directory);
    ``inputs``: name -> path of what the artifact was made from."""
    repo = Path(repo) if repo else Path.cwd()
    git_rev, dirty = None, None
    try:
        git_rev = _git(repo, "rev-parse", "HEAD", check=True) or None
        dirty = bool(_git(repo, "status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        pass
    return {
        "git_revision": git_rev,
        "git_dirty": dirty,
        "dvc": dvc_lock_info(repo, inputs),
    }


def _git(repo: Path, *args: str, check: bool = False) -> str:
    done = subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True,
                          check=check, timeout=10)
    return done.stdout.strip()


def dvc_lock_info(repo: Path, inputs: Mapping[str, str]) -> dict[str, Any] | None:
    """md5 of ``repo``/dvc.lock and the md5 it records for each of ``inputs`` (None without
    a readable dvc.lock)."""
    lock = repo / "dvc.lock"
    if not lock.is_file():
        return None
    import yaml

    try:
        data = yaml.safe_load(lock.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError:
        return None
    wanted = {str(Path(p)) for p in inputs.values()}
    md5 = {}
    for stage in (data.get("stages") or {}).values():
        for out in stage.get("outs", []) or []:
            if str(Path(out.get("path", ""))) in wanted:
                md5[out["path"]] = out.get("md5")
    return {"dvc_lock_md5": hashlib.md5(lock.read_bytes()).hexdigest(), "inputs_md5": md5}
