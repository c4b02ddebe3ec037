"""Scan statistics of the sim-to-real comparison (docs/design.md, "The sim-to-real
comparison"): points a scan, the range histogram, returns per ring (from the points' stored
order) and lost returns, on a tiny synthetic scan worked out by hand and on a real KITTI scan."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pipeline.sim.effects import SensorEffects
from pipeline.sim.raycast import Raycaster
from pipeline.sim.sensors import get_sensor
from pipeline.sim.simulate import SimSpec, make_world
from studies.realism.statistics import RANGE_EDGES_M, ring_of_points, scan_statistics

AZIMUTHS_DEG = tuple(-157.5 + 45.0 * k for k in range(8))
"""8 firings a ring, 45 deg apart, stored in ascending azimuth as KITTI and the simulator
store them."""
RING_RANGES_M = (3.0, 12.0, 50.0)
"""3 rings (beams), each at its own range: histogram bins 0-5, 10-15 and 40-60 m."""


def ring_scan(kept: dict[int, list[int]] | None = None) -> NDArray[np.float32]:
    """(N, 4) points of the 3-ring scan, ring after ring; ``kept``: ring -> the firings that
    returned (default all)."""
    rows = []
    for ring, r in enumerate(RING_RANGES_M):
        elevation = np.radians(2.0 - 2.0 * ring)
        for k, az in enumerate(np.radians(AZIMUTHS_DEG)):
            if kept is None or k in kept.get(ring, range(8)):
                rows.append([r * np.cos(elevation) * np.cos(az), r * np.cos(elevation) * np.sin(az),
                             r * np.sin(elevation), 0.5])
    return np.array(rows, np.float32)


def test_rings_are_found_by_angle_even_where_returns_are_missing() -> None:
    assert ring_of_points(ring_scan()).tolist() == [0] * 8 + [1] * 8 + [2] * 8
    # ring 0 lost its first firing, ring 1 its last, ring 2 its first and fifth: the widest
    # gap, from ring 1's 112.5 deg to ring 2's -112.5 deg, is 135 deg
    gappy = ring_scan({0: [1, 2, 3, 4, 5, 6, 7], 1: [0, 1, 2, 3, 4, 5, 6], 2: [1, 2, 3, 5, 6, 7]})
    assert ring_of_points(gappy).tolist() == [0] * 7 + [1] * 7 + [2] * 6


def test_rings_are_recovered_from_a_simulated_scans_stored_order() -> None:
    """Every return of a simulated scan gets its laser's ring back, from the order alone."""
    w = make_world(SimSpec("street", 1, 3))
    sensor = get_sensor("hdl32", SensorEffects.ideal())
    caster = Raycaster(w.vertices, w.triangles, sensor, w.materials)
    pts = caster.scan(w.poses.T_world_lidar[1], np.random.default_rng(0))
    el = np.degrees(np.arcsin(pts[:, 2] / np.linalg.norm(pts[:, :3], axis=1)))
    beam = np.abs(el[:, None] - np.array(sensor.elevations_deg)[None]).argmin(axis=1)
    assert (ring_of_points(pts) == beam).all()


def test_statistics_of_a_full_and_a_gappy_scan() -> None:
    """Scan 1 full (24 of 24 firings), scan 2 with 21 (ring 1 lost one, ring 2 two): 22.5
    points a scan, 1 - 22.5 / 24 lost; rings 8, 7.5, 7 returns a scan; range shares 16/45,
    15/45, 14/45 in the bins 0-5, 10-15, 40-60 m."""
    full = ring_scan()
    gappy = ring_scan({1: [0, 1, 3, 4, 5, 6, 7], 2: [0, 1, 2, 4, 6, 7]})
    stats = scan_statistics([full, gappy], beams=3, firings=24)
    assert stats.points == pytest.approx(22.5)
    assert stats.lost_share == pytest.approx(1.0 - 22.5 / 24.0)
    assert stats.ring_returns == pytest.approx((8.0, 7.5, 7.0))
    assert stats.rings_found == 3
    expected = np.zeros(len(RANGE_EDGES_M) - 1)
    expected[[RANGE_EDGES_M.index(0.0), RANGE_EDGES_M.index(10.0), RANGE_EDGES_M.index(40.0)]] = (
        16 / 45, 15 / 45, 14 / 45)
    assert stats.range_share == pytest.approx(tuple(expected))


def test_a_gap_of_half_a_turn_or_more_is_counted_as_rings_not_found() -> None:
    """Ring 1 returned only in its first half turn, ring 2 only in its second: in the order
    alone they read as one ring; the statistics say 2 rings recovered, not 3."""
    merged = ring_scan({1: [0, 1, 2, 3], 2: [4, 5, 6, 7]})
    stats = scan_statistics([ring_scan(), merged], beams=3, firings=24)
    assert stats.rings_found == 2
    assert stats.points == pytest.approx(20.0)


def test_a_real_kitti_scan_has_64_rings_from_top_to_bottom(kitti_root: Path) -> None:
    """KITTI stores an HDL-64E scan ring after ring: the recovered rings are the 64 lasers,
    their median elevation falling from the first ring to the last."""
    points = np.fromfile(kitti_root / "sequences" / "04" / "velodyne" / "000000.bin",
                         np.float32).reshape(-1, 4)
    ring = ring_of_points(points)
    assert ring.max() == 63 and np.all(np.diff(ring) >= 0)
    elevation = np.degrees(np.arctan2(points[:, 2], np.linalg.norm(points[:, :2], axis=1)))
    medians = [np.median(elevation[ring == k]) for k in range(64) if np.sum(ring == k) > 100]
    assert len(medians) >= 60
    assert np.all(np.diff(medians) < 0)
    stats = scan_statistics([points], beams=64, firings=64 * 2000)
    assert stats.points == len(points)
    assert sum(stats.ring_returns) == len(points)
