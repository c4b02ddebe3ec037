"""Per-point time of a scan, as drivers store it, -> float32 seconds relative to the scan stamp.

Spinning LiDARs stamp every point; the field and its unit differ by driver:
- integer fields count ns from the start of the scan (Ouster ``t`` uint32, Livox
  ``offset_time`` uint32);
- float fields are seconds: relative to the scan (Velodyne ``time``, often negative: before the
  stamp) or absolute, since the epoch (Hesai / RoboSense ``timestamp``; values above 1e6 s).
The sequence MCAP keeps them as the PointCloud2 field ``time`` (pipeline.ros2_cdr.TIME_FIELD),
so adapters that deskew (KISS-ICP) can use them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError

ABSOLUTE_AFTER_S = 1e6
"""Float times above this are seconds since the epoch, not since the scan's start."""
MAX_SPREAD_S = 10.0
"""A scan's per-point times span less than this (a sweep takes 0.05-1 s)."""


def relative_times_s(values: NDArray, field: str, stamp_ns: int, what: str) -> NDArray[np.float32]:
    """(N,) float32 seconds relative to ``stamp_ns`` of the per-point time column ``values``.

    InputError naming ``what`` and ``field`` for non-finite times or times that span more than
    MAX_SPREAD_S (another unit than the ones above).
    """
    v = np.asarray(values)
    if v.dtype.kind in "iu":
        rel = v.astype(np.float64) * 1e-9
    else:
        rel = v.astype(np.float64)
        if not np.isfinite(rel).all():
            raise InputError(f"{what}: per-point time field {field!r} has non-finite values")
        if len(rel) and np.abs(rel).max() > ABSOLUTE_AFTER_S:
            rel = rel - int(stamp_ns) / 1e9
    if len(rel) and (np.abs(rel).max() > MAX_SPREAD_S):
        raise InputError(
            f"{what}: per-point time field {field!r} spans {np.ptp(rel):.3g} s around the scan "
            f"stamp (expected < {MAX_SPREAD_S:g} s: integers in ns, floats in s relative or "
            "since the epoch)"
        )
    return rel.astype(np.float32)
