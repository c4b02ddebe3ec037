"""The project's DVC cache stores an output once (docs/design.md, "Stages"): `.dvc/config` links
the cache's files into the workspace, so DVC's commit of a stage's outputs (31 GB of MCAPs for
the verdict's tuning suite) does not copy them."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def dvc(cwd: Path, *args: str) -> None:
    done = subprocess.run([str(BIN / "dvc"), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, f"dvc {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"


def test_a_committed_output_is_linked_into_the_cache_not_copied(tmp_path: Path) -> None:
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    dvc(tmp_path, "init", "-q")
    shutil.copy(REPO / ".dvc" / "config", tmp_path / ".dvc" / "config")
    (tmp_path / "data").mkdir()
    scan = tmp_path / "data" / "world.mcap"
    scan.write_bytes(os.urandom(1 << 20))
    dvc(tmp_path, "add", "data/world.mcap")
    cached = [p for p in (tmp_path / ".dvc" / "cache").rglob("*") if p.is_file()]
    assert len(cached) == 1 and os.path.samefile(cached[0], scan)  # one file, two names
