"""numba's compiled-kernel cache goes to a user cache folder, never into the installed package
(issue 14, item 8): a read-only install works."""

from __future__ import annotations

import ast
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

SCRIPT = """
import numpy as np
from pipeline.descriptors.ndt_histogram_kernel import voxel_moments_dense
pts = np.random.default_rng(0).normal(0, 5, (2000, 3)).astype(np.float32)
ok = voxel_moments_dense(pts, 1.0, 50.0, 3, 10**6)[0]
print("ok", bool(ok))
"""
"""One kernel compiled in the read-only copy: the cache folder is set once for every kernel
(pipeline/__init__.py), and each kernel opts in with ``cache=True``
(test_every_kernel_is_compiled_with_the_cache); compiling all of them there took 41 s."""


def njit_calls(path: Path) -> list[ast.Call]:
    """The ``numba.njit(...)`` / ``njit(...)`` decorator calls of a module."""
    calls = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for dec in node.decorator_list:
                target = dec.func if isinstance(dec, ast.Call) else dec
                name = target.attr if isinstance(target, ast.Attribute) else getattr(
                    target, "id", "")
                if name in ("njit", "jit"):
                    calls.append(dec)
    return calls


def test_every_kernel_is_compiled_with_the_cache() -> None:
    """Every numba kernel of the package is ``njit(cache=True, ...)``: compiled once into the
    user cache folder, not at every start of a process (and never beside the module)."""
    found = [(path, call) for path in sorted((REPO / "pipeline").rglob("*.py"))
             for call in njit_calls(path)]
    assert len(found) >= 40, "the kernels were not found: is numba still the compiler?"
    uncached = [f"{path.relative_to(REPO)}:{call.lineno}" for path, call in found
                if not (isinstance(call, ast.Call) and any(
                    k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True
                    for k in call.keywords))]
    assert uncached == []


def test_kernels_cache_in_the_user_cache_dir_not_the_package(tmp_path: Path) -> None:
    """A read-only copy of the package runs a cached numba kernel (the descriptor's): its cache
    files appear under $XDG_CACHE_HOME/adaptune/numba and none inside the package."""
    pkg = tmp_path / "site"
    shutil.copytree(REPO / "pipeline", pkg / "pipeline",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "schemas", pkg / "schemas",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for path in [pkg, *pkg.rglob("*")]:  # read-only, as an installed package may be
        path.chmod(path.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(pkg), XDG_CACHE_HOME=str(tmp_path / "cache"),
               PYTHONDONTWRITEBYTECODE="1")
    try:
        done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0 and "ok" in done.stdout, done.stderr
        written = [p for p in pkg.rglob("*") if p.is_file() and p.suffix in (".nbi", ".nbc")]
        assert written == []
        cached = {p.name.split(".")[1].split("-")[0]
                  for p in (tmp_path / "cache" / "adaptune" / "numba").rglob("*.nbi")}
        assert "voxel_moments_dense" in cached, cached
    finally:
        for path in [pkg, *pkg.rglob("*")]:
            path.chmod(path.stat().st_mode | stat.S_IWUSR)
