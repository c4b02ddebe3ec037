"""KISS-ICP's own command line (``kiss_icp_pipeline``) as a black-box odometry for adaptune.

adaptune's ``command`` adapter runs this script once per trial (docs/usage.md, "Your own
odometry"):

    python kiss_icp_tool.py SCANS PARAMS.json OUT.txt

SCANS is a KITTI-layout folder (``velodyne/NNNNNN.bin``, ``times.txt``: the adapter's
``scans: kitti`` option), PARAMS.json the parameters adaptune chose ({name: value}; the names
of space.yaml). The script maps them onto KISS-ICP's configuration file, runs
``kiss_icp_pipeline --config CONFIG SCANS/velodyne`` (its generic loader reads KITTI .bin
scans), and copies the poses it writes (``<out_dir>/latest/velodyne_poses_kitti.txt``: one
T_world_lidar a line, 12 numbers, the first the identity) to OUT.txt.

It imports nothing of adaptune: the standard library only. A tool of your own takes the place of
``kiss_icp_pipeline`` the same way: read the scans folder (or the sequence MCAP, or PCD files),
read the parameters, write one pose a scan.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

CONFIG = {  # KISS-ICP's configuration keys (kiss_icp.config) of each tuned parameter
    "max_range": ("data", "max_range"),
    "min_range": ("data", "min_range"),
    "voxel_size": ("mapping", "voxel_size"),
    "max_points_per_voxel": ("mapping", "max_points_per_voxel"),
    "initial_threshold": ("adaptive_threshold", "initial_threshold"),
    "min_motion_th": ("adaptive_threshold", "min_motion_th"),
}
INTEGERS = ("max_points_per_voxel",)


def kiss_config(params: dict[str, float], out_dir: Path) -> dict:
    """KISS-ICP's configuration for ``params``: untuned settings as adaptune's own kiss_icp
    adapter has them on scans without per-point time (no deskewing: the .bin files carry no
    time; one thread)."""
    config: dict = {"out_dir": str(out_dir), "data": {"deskew": False},
                    "registration": {"max_num_threads": 1}}
    for name, value in params.items():
        if name not in CONFIG:
            raise SystemExit(f"kiss_icp_tool: unknown parameter {name!r} (known: "
                             f"{', '.join(CONFIG)})")
        section, key = CONFIG[name]
        config.setdefault(section, {})[key] = round(value) if name in INTEGERS else value
    return config


def kiss_icp_pipeline() -> str:
    """KISS-ICP's command: beside this interpreter (a virtualenv), else on PATH."""
    beside = Path(sys.executable).with_name("kiss_icp_pipeline")
    if beside.exists():
        return str(beside)
    return shutil.which("kiss_icp_pipeline") or "kiss_icp_pipeline"


def main(scans: str, params_json: str, out: str) -> int:
    params = json.loads(Path(params_json).read_text())
    with tempfile.TemporaryDirectory(prefix="kiss_icp_tool-") as tmp:
        config = Path(tmp) / "config.yaml"
        config.write_text(json.dumps(kiss_config(params, Path(tmp) / "results")))  # JSON is YAML
        done = subprocess.run([kiss_icp_pipeline(), "--config", str(config),
                               str(Path(scans) / "velodyne")],
                              capture_output=True, text=True, env={**os.environ, "NO_COLOR": "1"})
        if done.returncode != 0:
            lines = (done.stderr or done.stdout).strip().splitlines()
            print(f"kiss_icp_pipeline failed: {lines[-1] if lines else done.returncode}",
                  file=sys.stderr)
            return 1
        poses = Path(tmp) / "results" / "latest" / "velodyne_poses_kitti.txt"
        shutil.copy(poses, out)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__.split("\n\n")[1])
    sys.exit(main(*sys.argv[1:]))
