"""Shared fixtures. Real KITTI data comes from ADAPTUNE_TEST_DATA (default ../shared/data).

Where that folder is missing, tests that need it skip with the reason; with CI=true that is
a failure instead, so CI never goes green without the real data.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def pytest_configure(config: pytest.Config) -> None:
    """The DVC projects the tests create (`dvc init` in a temporary folder) send no usage
    analytics: DVC's analytics daemon leaves a report file in the system's temporary folder
    for every command when it cannot send it (this machine has no network)."""
    os.environ["DVC_NO_ANALYTICS"] = "1"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The modules marked ``slow`` (the DVC projects, each one to three minutes) first, then the
    rest, each group by its number of tests (xdist's own order). `make test` hands modules out
    in this order (``--dist loadfile --no-loadscope-reorder``): the longest jobs start first and
    the short ones fill the gaps at the end, so no worker starts a three-minute module last."""
    per_module = Counter(item.nodeid.split("::")[0] for item in items)
    items.sort(key=lambda item: (item.get_closest_marker("slow") is None,
                                 -per_module[item.nodeid.split("::")[0]]))


def _data_root() -> Path:
    env = os.environ.get("ADAPTUNE_TEST_DATA")
    return Path(env) if env else (REPO / ".." / "shared" / "data").resolve()


@pytest.fixture(scope="session")
def test_data() -> Path:
    """Root of the real test data (kitti_mini/, kitti_trajectories/, real/)."""
    root = _data_root()
    if not (root / "kitti_mini").is_dir():
        msg = f"real test data not found at {root} (set ADAPTUNE_TEST_DATA)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return root


@pytest.fixture(scope="session")
def real_runs(test_data: Path) -> Path:
    """Folder of the four real runs with a SLAM reference (hku_1, hku_mb, quick_shack,
    riverside02: scans/, poses.txt, odom_poses.txt, times.txt; its README.md)."""
    root = test_data / "real"
    if not (root / "hku_1" / "poses.txt").is_file():
        msg = f"real runs not found at {root} (set ADAPTUNE_TEST_DATA)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return root


@pytest.fixture(scope="session")
def kitti_root(test_data: Path) -> Path:
    """KITTI odometry root with sequences/ and poses/ (sequences 01, 04, 06, 10; frames 0-9)."""
    return test_data / "kitti_mini" / "dataset"


@pytest.fixture(scope="session")
def kitti_trajectories(test_data: Path) -> Path:
    """Folder of the official ground-truth pose files 00.txt .. 10.txt (camera frame)."""
    return test_data / "kitti_trajectories"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)
