"""Scan statistics of a spinning LiDAR: points per scan, range histogram, returns per ring, lost
returns (docs/design.md, "The sim-to-real comparison").

Rings are recovered from the points' order, as KITTI stores them and the simulator writes them:
ring after ring (beam-major), each ring one revolution in ascending azimuth. The unwrapped
azimuth then grows by 2 pi a ring; the seam between rings lies in the gap between the scan's
last point and its first point one revolution on, so a ring is found by angle alone, with
returns missing anywhere, as long as no gap between consecutive points (within a ring, or
from a ring's last point to the next ring's first) spans half a revolution or more: the
unwrapping reads such a gap as a step backwards (KITTI's own points step back by up to
180 deg within a ring on highways, so a wider threshold would misread them). A scan with such
a gap yields fewer rings than the sensor has; ``ScanStatistics.rings_found`` says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

RANGE_EDGES_M = (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 60.0, 80.0, 200.0)
"""Edges of the range histogram [m]."""


def ring_of_points(points_lidar: NDArray[np.float32]) -> NDArray[np.int64]:
    """(N,) ring index (0 = the first ring stored) of the (N, >=3) points of one scan stored
    ring after ring in ascending azimuth (module docstring)."""
    if len(points_lidar) < 2:
        return np.zeros(len(points_lidar), np.int64)
    u = np.unwrap(np.arctan2(points_lidar[:, 1], points_lidar[:, 0]).astype(np.float64))
    n = max(1, round((u[-1] - u[0]) / (2 * np.pi)))
    seam = 0.5 * (u[-1] + u[0] + 2 * np.pi * n)
    ring = np.floor((u - seam) / (2 * np.pi)).astype(np.int64) + n
    return np.clip(ring, 0, n - 1)


@dataclass(frozen=True)
class ScanStatistics:
    """Statistics over the scans of a slice.

    points: mean points per scan; range_share: (len(RANGE_EDGES_M) - 1,) share of the points
    in each range bin; ring_returns: (R,) mean returns per ring and scan; lost_share: mean share
    of the sensor's firings (``firings`` a scan) that gave no point; rings_found: the fewest
    rings recovered from any scan (module docstring): below R, ring_returns is off for the
    rings after the first gap it missed.
    """

    points: float
    range_share: tuple[float, ...]
    ring_returns: tuple[float, ...]
    lost_share: float
    rings_found: int


def scan_statistics(scans: list[NDArray[np.float32]], beams: int,
                    firings: int) -> ScanStatistics:
    """Statistics of ``scans`` ((N_k, >=3) float32 points [m], lidar frame, stored ring after
    ring) of a sensor with ``beams`` rings and ``firings`` firings a scan."""
    counts = np.array([len(p) for p in scans], np.float64)
    ranges = np.concatenate([np.linalg.norm(p[:, :3], axis=1) for p in scans])
    hist = np.histogram(ranges, bins=RANGE_EDGES_M)[0].astype(np.float64)
    rings = np.zeros(beams)
    found = beams
    for p in scans:
        ring = ring_of_points(p)
        rings += np.bincount(ring, minlength=beams)[:beams]
        found = min(found, int(ring.max()) + 1 if len(ring) else 0)
    return ScanStatistics(
        float(counts.mean()),
        tuple((hist / max(1.0, hist.sum())).tolist()),
        tuple((rings / len(scans)).tolist()),
        float(1.0 - counts.mean() / firings),
        found,
    )
