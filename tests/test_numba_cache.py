"""numba's compiled-kernel cache goes to a user cache folder, never into the installed package
(issue 14, item 8): a read-only install works."""

from __future__ import annotations

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
from pipeline.odometry.base import Schedule
from pipeline.odometry.ndt import NdtAdapter
from pipeline.sequence import Scan
scans = [Scan(k, k * 10**8, np.c_[pts + [0.1 * k, 0, 0], np.zeros(2000)].astype(np.float32))
         for k in range(2)]
ndt = NdtAdapter()
ndt.run(scans, Schedule.constant(ndt.space.defaults(), 2))  # the issue's case: an NDT run
from pipeline.sim.simulate import SimSpec, iter_scans, make_world
spec = SimSpec("cave", 1, 2, "vlp16")  # the simulator's per-return kernel
scan = next(iter_scans(make_world(spec), spec.sensor_model(), 1, motion=spec.motion))
print("ok", bool(ok) and len(scan.points_lidar) > 0)
"""


def test_kernels_cache_in_the_user_cache_dir_not_the_package(tmp_path: Path) -> None:
    """A read-only copy of the package runs its cached numba kernels (the descriptor's, NDT's
    in an NDT run, the simulator's in a simulated scan: rays, relief, returns): cache files
    appear under $XDG_CACHE_HOME/adaptune/numba and none inside the package."""
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
        assert {"voxel_moments_dense", "ndt_terms", "shape_returns", "draw_uniforms", "turn_rays",
                "rough_hits"} <= cached, cached
    finally:
        for path in [pkg, *pkg.rglob("*")]:
            path.chmod(path.stat().st_mode | stat.S_IWUSR)
