"""Fixtures of the odometry contract suite: sequences (synthetic and real KITTI), adapters."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.odometry_data import Seq, make_adapter, write_kitti_sequence, write_synthetic_sequence

from pipeline.odometry import adapter_names


@pytest.fixture(params=adapter_names())
def adapter(request: pytest.FixtureRequest):
    """Every registered adapter (``command`` drives tests/odometry/scripts/s2s_gicp.py)."""
    return make_adapter(request.param)


@pytest.fixture(scope="session")
def synthetic_seq(tmp_path_factory: pytest.TempPathFactory) -> Seq:
    """20 frames of a ray-cast HDL-32E (900 azimuth steps, ~28k points) at 0.8 m a frame."""
    path = tmp_path_factory.mktemp("odom") / "yard.mcap"
    return Seq(write_synthetic_sequence(path, n_frames=20, step_m=0.8, azimuth_steps=900))


@pytest.fixture(scope="session")
def kitti_seq(kitti_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Seq:
    """Real KITTI sequence 04, frames 0-9 (HDL-64E, ~120k points a scan, 11.9 m)."""
    path = tmp_path_factory.mktemp("odom") / "kitti04.mcap"
    return Seq(write_kitti_sequence(path, kitti_root, "04", 10))
