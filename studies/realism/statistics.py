"""Scan statistics of a spinning LiDAR: points per scan, range histogram, returns per ring, lost
returns (docs/design.md, "The sim-to-real comparison").

Rings are recovered from the points' order, as KITTI stores them and the simulator writes them:
ring after ring (beam-major), each ring one revolution in ascending azimuth. The unwrapped
azimuth then grows by 2 pi a ring, so a ring is found by angle alone, however many of its
returns are missing, once the seam (the azimuth where every ring starts) is known: it is taken
at the end of the scan that belongs to the lowest ring (the first point when the first ring
looks lower than the last, else the last point), which sees the ground all round and so
starts and ends at the seam. This holds as long as no gap between consecutive points (within a
ring, or from a ring's last point to the next ring's first) spans half a revolution or more:
the unwrapping reads such a gap as a step backwards (KITTI's own points step back by up to
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
    p = points_lidar[:, :3].astype(np.float64)
    u = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))
    el = np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]))
    k = min(50, len(p))
    if np.median(el[:k]) < np.median(el[-k:]):  # the first ring is the lowest
        return np.floor((u - u[0] + 1e-6) / (2 * np.pi)).astype(np.int64)
    # the last ring is the lowest; the first ring may start a little before the seam
    n = max(1, int(np.ceil((u[-1] - u[0]) / (2 * np.pi) - 0.05)))
    ring = np.floor((u - u[-1] - 1e-6) / (2 * np.pi)).astype(np.int64) + n
    return np.clip(ring, 0, n - 1)


@dataclass(frozen=True)
class ScanStatistics:
    """Statistics over the scans of a slice.

    points: mean points per scan; range_share: (len(RANGE_EDGES_M) - 1,) share of the points
    in each range bin; ring_returns: (R,) mean returns per ring and scan; lost_share: mean share
    of the sensor's firings (``firings`` a scan) that gave no point; rings_found: the fewest
    rings recovered from any scan (module docstring): below R, ring_returns is off for the
    rings after the first gap it missed; road_planarity_mm: the median thickness of the road
    4-10 m around the car (``road_planarity``): range noise and the rings' disagreement, seen
    across the road.
    """

    points: float
    range_share: tuple[float, ...]
    ring_returns: tuple[float, ...]
    lost_share: float
    rings_found: int
    road_planarity_mm: float


def road_planarity(points_lidar: NDArray[np.float32], near_m: float = 4.0,
                   far_m: float = 10.0, patch_m: float = 0.5) -> float:
    """Median over 0.5 m patches (8 points or more) of the road within 3 m of the car's path
    and ``near_m`` .. ``far_m`` away (points below -1.2 m) of the smallest standard deviation
    of the patch's points (the plane's thickness) [mm]."""
    q = points_lidar[:, :3].astype(np.float64)
    rho = np.hypot(q[:, 0], q[:, 1])
    q = q[(rho > near_m) & (rho < far_m) & (np.abs(q[:, 1]) < 3.0) & (q[:, 2] < -1.2)]
    if not len(q):
        return float("nan")
    keys = np.floor(q[:, :2] / patch_m).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    thickness = []
    for k in np.flatnonzero(counts >= 8):
        c = q[inverse == k]
        c = c - c.mean(axis=0)
        thickness.append(np.sqrt(max(np.linalg.eigvalsh(c.T @ c / len(c))[0], 0.0)))
    return float(1000.0 * np.median(thickness)) if thickness else float("nan")


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
        _median_of_finite([road_planarity(p) for p in scans]),
    )


def _median_of_finite(values: list[float]) -> float:
    """Median of the finite ``values``; NaN when there is none (a scan without road)."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.median(finite)) if finite else float("nan")
