"""What a long loop shows while it runs: a progress bar on a terminal, log lines elsewhere.

The one home of the ``pipeline.progress`` logger (the CLI keeps it at INFO whatever its
verbosity, stages/cli.py). ``progress(items, total, what, unit)`` wraps the frames of an ingest,
a simulation or an odometry run: on a terminal (stderr is a tty) a tqdm bar; without one
(``dvc repro`` in CI, a log file) a line when the loop starts, after every tenth of ``total``
items (every ``UNKNOWN_EVERY`` items when the total is unknown) with the pace and an ETA, at
most one every ``min_interval_s`` (``MIN_INTERVAL_S``: a loop of seconds logs its start and
end only), and when it ends. A study's trials do the same in ``pipeline.tuning.progress``.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

PROGRESS = logging.getLogger("pipeline.progress")
"""Progress lines (INFO); the CLI keeps this logger at INFO whatever its verbosity."""
UNKNOWN_EVERY = 100
"""A log line every this many items when the total is not known up front."""
MIN_INTERVAL_S = 5.0
"""No two progress lines of a loop closer than this [s] (its last line aside)."""

T = TypeVar("T")


def progress(items: Iterable[T], total: int | None, what: str, unit: str = "frame",
             enabled: bool = True, terminal: bool | None = None,
             min_interval_s: float = MIN_INTERVAL_S) -> Iterator[T]:
    """``items``, passed through, with progress shown (module docstring).

    ``what``: what the loop does, e.g. ``ingest drive1``; ``unit``: what an item is;
    ``enabled`` False shows nothing; ``terminal`` overrides whether stderr is a tty.
    """
    if not enabled:
        yield from items
        return
    if sys.stderr.isatty() if terminal is None else terminal:
        from tqdm import tqdm

        yield from tqdm(items, total=total, desc=what, unit=unit, file=sys.stderr,
                        dynamic_ncols=True, leave=False)
        return
    yield from _logged(items, total, what, unit, min_interval_s)


def _logged(items: Iterable[T], total: int | None, what: str, unit: str,
            min_interval_s: float) -> Iterator[T]:
    every = max(1, math.ceil(total / 10)) if total else UNKNOWN_EVERY
    PROGRESS.info("%s: %s %ss", what, total if total is not None else "?", unit)
    t0 = last = time.monotonic()
    done = 0
    for item in items:
        yield item
        done += 1
        now = time.monotonic()
        if done % every == 0 and done != total and now - last >= min_interval_s:
            PROGRESS.info("%s: %s", what, _line(done, total, unit, now - t0))
            last = now
    PROGRESS.info("%s finished: %d %ss in %s", what, done, unit,
                  duration(time.monotonic() - t0))


def _line(done: int, total: int | None, unit: str, seconds: float) -> str:
    """``120/1050 frames, 14.2 frames/s, ETA 1.1 min``."""
    rate = done / seconds if seconds > 0 else math.inf
    shown = f"{done}/{total}" if total else str(done)
    eta = f", ETA {duration((total - done) / rate)}" if total and rate > 0 else ""
    return f"{shown} {unit}s, {rate:.3g} {unit}s/s{eta}"


def duration(seconds: float) -> str:
    """``12 s``, ``5.2 min`` or ``1.3 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"
