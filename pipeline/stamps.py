"""Scan stamps: the range a sequence MCAP can hold, seconds -> ns, and times files.

A stamp is an int64 count of ns since the epoch (or since the start of the recording, as KITTI's
times.txt). It must lie in [0, 2^31) s: ROS 2 ``builtin_interfaces/Time.sec`` is an int32, so
later stamps (after 2038-01-19) cannot be written, and negative ones are not sensor times.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.io_utils import read_input_text

MAX_STAMP_S = 2**31
"""Stamps must be below 2^31 s (ROS 2 Time.sec is int32)."""
RANGE_RULE = "stamps must be in [0, 2^31) s (ROS 2 Time.sec is an int32)"


def check_stamp_ns(stamp_ns: int, what: str) -> int:
    """``stamp_ns`` as an int when it is in [0, 2^31) s; InputError naming ``what`` otherwise."""
    stamp = int(stamp_ns)
    if not 0 <= stamp < MAX_STAMP_S * 1_000_000_000:
        raise InputError(f"{what}: stamp {stamp / 1e9:.9g} s is out of range ({RANGE_RULE})")
    return stamp


def seconds_to_ns(t_s: NDArray[np.float64], what: str) -> NDArray[np.int64]:
    """(N,) int64 ns of stamps in seconds, checked finite and in range (no int64 overflow)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    bad = ~np.isfinite(t_s) | (t_s < 0) | (t_s >= MAX_STAMP_S)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(f"{what}: stamp {k} is {float(t_s[k])!r} s ({RANGE_RULE}, finite)")
    return np.round(t_s * 1e9).astype(np.int64)


def decimal_seconds_to_ns(token: str, what: str) -> int:
    """Exact ns of a decimal seconds string (a float64 would lose ~200 ns at epoch times)."""
    try:
        value = Decimal(token)
    except InvalidOperation:
        raise InputError(f"{what}: stamp {token!r} is not a number") from None
    if not value.is_finite() or not 0 <= value < MAX_STAMP_S:
        raise InputError(f"{what}: stamp {token} s is out of range ({RANGE_RULE})")
    return int((value * 1_000_000_000).to_integral_value())


def read_times(path: Path, n_scans: int | None) -> NDArray[np.int64]:
    """(n_scans,) stamps [ns] from a times file: one number a line, seconds (KITTI times.txt);
    every line's when ``n_scans`` is None.

    InputError names the file and line for anything else: two columns, a word, a negative or
    too large time, a count that does not match, stamps that do not increase.
    """
    text = read_input_text(path, "times file")
    stamps: list[int] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != 1:
            raise InputError(f"{path} line {lineno}: {len(fields)} values, a times file has one "
                             "number a line (seconds)")
        stamps.append(decimal_seconds_to_ns(fields[0], f"{path} line {lineno}"))
    if n_scans is not None and len(stamps) != n_scans:
        raise InputError(f"{path}: {len(stamps)} stamps for {n_scans} scans")
    out = np.array(stamps, np.int64)
    if np.any(np.diff(out) <= 0):
        k = int(np.flatnonzero(np.diff(out) <= 0)[0]) + 1
        raise InputError(f"{path}: stamps must be strictly increasing (stamp {k} is not after "
                         f"stamp {k - 1})")
    return out
