"""The order of scan files in a folder: by the numbers in their names, never as plain strings.

Plain string order puts ``full10`` before ``full2`` (a 177-scan run got 175 scans paired with
another scan's pose that way, without a word). Here the names must follow one pattern whose only
varying parts are numbers (``full0 .. full176``, ``000000 .. 004540``, ``1317000000.123456``):
they are sorted by those numbers. Names that differ in anything else, or two names with the same
numbers (``scan1`` and ``scan01``), are refused, since no order can be trusted.

Names that are stamps (a decimal number with a fraction, seconds; or an integer of 18 or more
digits, ns) also give each scan its stamp (``name_stamps_ns``).
"""

from __future__ import annotations

import itertools
import logging
import re
from decimal import Decimal
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.stamps import decimal_seconds_to_ns

log = logging.getLogger(__name__)

_NUMBER = re.compile(r"\d+")
_SECONDS = re.compile(r"\d+\.\d+")
_NANOSECONDS = re.compile(r"\d{18,}")


def natural_order(files: list[Path], what: str) -> list[Path]:
    """``files`` sorted by the numbers in their stems (module docstring); InputError naming
    ``what`` and two offending names when the names do not allow one order."""
    if len(files) < 2:
        return list(files)
    keyed = []
    decimal_stems = all(_SECONDS.fullmatch(p.stem) for p in files)  # stamps [s]: by value
    for path in files:
        template = _NUMBER.sub("#", path.stem)
        numbers = ((Decimal(path.stem),) if decimal_stems
                   else tuple(Decimal(n) for n in _NUMBER.findall(path.stem)))
        keyed.append((template, numbers, path))
    templates = {t for t, _, _ in keyed}
    if len(templates) > 1:
        a, b = sorted(templates)[:2]
        ex_a = next(p.name for t, _, p in keyed if t == a)
        ex_b = next(p.name for t, _, p in keyed if t == b)
        raise InputError(f"{what}: cannot order the scans by name: {ex_a!r} and {ex_b!r} differ "
                         "in more than their numbers (name them <prefix><number>, one pattern)")
    if "#" not in templates.pop():
        raise InputError(f"{what}: cannot order the scans by name: the names carry no number "
                         f"({keyed[0][2].name!r}, {keyed[1][2].name!r}, ...)")
    keyed.sort(key=lambda k: k[1])
    for (_, n0, p0), (_, n1, p1) in itertools.pairwise(keyed):
        if n0 == n1:
            raise InputError(f"{what}: cannot order the scans by name: {p0.name!r} and "
                             f"{p1.name!r} carry the same number")
    return [p for _, _, p in keyed]


def frame_numbers(files: list[Path]) -> NDArray[np.int64] | None:
    """(N,) the frame numbers of scans named by them (``000123.pcd``, KITTI's way), or None."""
    if not files or not all(p.stem.isdigit() for p in files):
        return None
    return np.array([int(p.stem) for p in files], np.int64)


def rows_for_scans(rows: int, n_scans: int, numbers: NDArray[np.int64] | None, what: str,
                   kind: str) -> NDArray[np.int64]:
    """Which rows of a file with one row a frame (a times file, poses without stamps) belong to
    the scans: row k to scan k when the counts match; for scans named by frame number and a
    longer file (a slice of a KITTI sequence with its full times.txt and poses), row n to
    ``n.pcd``. InputError naming ``what`` otherwise."""
    if rows == n_scans:
        return np.arange(n_scans, dtype=np.int64)
    if numbers is not None and rows > int(numbers.max()):
        log.warning("%s: %d %s for %d scans: scan n takes row n (line n + 1), numbering from "
                    "0 as KITTI's: lines %s used", what, rows, kind, n_scans,
                    lines_used(numbers, rows))
        return numbers
    raise InputError(f"{what}: {rows} {kind} for {n_scans} scans in {what_of(numbers)}")


def lines_used(rows: NDArray[np.int64], total: int) -> str:
    """Which lines (1-based, as an editor shows them) of a file of ``total`` rows ``rows``
    are: ``"2-10 of 10"``, or ``"1, 3, 5 of 9"`` when they are not one run."""
    first, last = int(rows.min()) + 1, int(rows.max()) + 1
    if len(rows) == last - first + 1 and bool(np.all(np.diff(rows) == 1)):
        return f"{first}-{last} of {total}"
    shown = ", ".join(str(int(r) + 1) for r in rows[:6])
    return f"{shown}{', ...' if len(rows) > 6 else ''} of {total}"


def what_of(numbers: NDArray[np.int64] | None) -> str:
    return ("the folder" if numbers is None
            else f"the folder (scans numbered {numbers.min()}..{numbers.max()})")


def name_stamps_ns(files: list[Path]) -> NDArray[np.int64] | None:
    """(N,) stamps [ns] when every stem is a stamp (``1317000000.123456`` seconds, or an integer
    of 18+ digits in ns), else None."""
    stems = [p.stem for p in files]
    if all(_SECONDS.fullmatch(s) for s in stems):
        return np.array([decimal_seconds_to_ns(s, str(p)) for s, p in zip(stems, files,
                                                                           strict=True)], np.int64)
    if all(_NANOSECONDS.fullmatch(s) for s in stems):
        return np.array([decimal_seconds_to_ns(str(Decimal(s) / 10**9), str(p))
                         for s, p in zip(stems, files, strict=True)], np.int64)
    return None
