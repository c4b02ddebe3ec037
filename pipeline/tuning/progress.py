"""What a study shows while it runs: a progress bar on a terminal, log lines elsewhere.

On a terminal (stderr is a tty) a tqdm bar per study with the best objective and the failed
count. Without one (``dvc repro`` in CI, a log file) a line on the ``pipeline.progress`` logger
when the study starts, every ``every`` finished trials (a tenth of the study by default) and
when it ends: done, failed, pruned, lost, best, ETA (from this run's pace).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping
from typing import Any

from pipeline.progress import PROGRESS, duration
from pipeline.tuning.job import TrialResult


class StudyProgress:
    """Progress of one study of ``total`` trials, ``initial`` of them finished before."""

    def __init__(self, name: str, total: int, initial: int, enabled: bool = True,
                 every: int | None = None, terminal: bool | None = None) -> None:
        self.name = name
        self.total = total
        self.initial = initial
        self.enabled = enabled
        self.every = every or max(1, math.ceil(total / 10))
        self.terminal = sys.stderr.isatty() if terminal is None else terminal
        self.ran = 0
        self.t0 = time.monotonic()
        self.bar: Any = None
        self.done: Mapping[int, TrialResult] = {}

    def __enter__(self) -> StudyProgress:
        if not self.enabled:
            return self
        if self.terminal:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, initial=self.initial, desc=self.name,
                            unit="trial", file=sys.stderr, dynamic_ncols=True)
        elif self.initial < self.total:
            PROGRESS.info("%s: %d trials, %d finished before", self.name, self.total,
                          self.initial)
        return self

    def update(self, done: Mapping[int, TrialResult]) -> None:
        """After every finished trial (``done``: every finished trial of the study, any
        status)."""
        self.ran += 1
        self.done = done
        if not self.enabled:
            return
        if self.bar is not None:
            best, counts = _best(done), _counts(done)
            self.bar.set_postfix(best=f"{best[1]:.4g}%" if best else "-",
                                 failed=counts["failed"], refresh=False)
            self.bar.update(1)
        elif self.ran % self.every == 0 and len(done) < self.total:
            PROGRESS.info("%s: %s", self.name, self.line(done))

    def line(self, done: Mapping[int, TrialResult]) -> str:
        """``64/256 done, 2 failed, 0 pruned, 0 lost, best 0.81 % (trial 41), ETA 5.2 min``."""
        counts = _counts(done)
        best = _best(done)
        left = self.total - len(done)
        pace_s = (time.monotonic() - self.t0) / max(self.ran, 1)
        eta = f"ETA {duration(left * pace_s)}" if left and self.ran else "done"
        shown = f"best {best[1]:.4g} % (trial {best[0]})" if best else "no ok trial yet"
        return (f"{len(done)}/{self.total} done, {counts['failed']} failed, "
                f"{counts['pruned']} pruned, {counts['lost']} lost, {shown}, {eta}")

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.enabled and self.ran:
            PROGRESS.info("%s finished: %s in %s (%d run now)", self.name,
                          self.line(self.done), duration(time.monotonic() - self.t0),
                          self.ran)


def _counts(done: Mapping[int, TrialResult]) -> dict[str, int]:
    out = {"ok": 0, "failed": 0, "pruned": 0, "lost": 0}
    for r in done.values():
        out[r.status] = out.get(r.status, 0) + 1
    return out


def _best(done: Mapping[int, TrialResult]) -> tuple[int, float] | None:
    ok = [(r.objective, r.trial) for r in done.values() if r.status == "ok"]
    if not ok:
        return None
    objective, trial = min(ok)
    return trial, objective

