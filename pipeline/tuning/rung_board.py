"""The rung board of a successive-halving study: the trials post their values as they pass the
rungs, and a trial at a rung reads every earlier trial's there (docs/design.md, "Stages").

Successive halving ranks trial t at rung r against the trials before it, ids 0..t-1, that
reached r. Thresholds set when a trial starts could only use the trials finished by then
(0..t-lag, ``pipeline.tuning.smbo.told_lag``): with 16 workers the first 31 trials would run
whole and every threshold would lag 31 trials. Here the trials post at every rung, so trial t
waits at its rung for the earlier trials that are still before it, and its threshold depends
on trial ids only: the same for any number of workers and any finishing order, so the bench
measures a 16-worker study's promotion by running it one trial at a time.

An earlier trial counts at rung r with its value there (also if it stopped or failed later;
NaN, no segment ended yet, counts as no value); it drops out once it has *ended* before r
(stopped, failed, finished; or lost for good, marked by the runner). A trial waits at most
``wait_limit_s`` for the rest (twice its time limit, which leaves the wait out: an earlier
trial that has not reached the rung by then is stuck, or queued behind this one on an executor
with fewer slots than trials in flight, and is left out, with a warning). Without a time limit
a trial waits as long as it takes: the runner then needs every trial in flight running.

Layout: ``<OUT>/rungs/algorithm=<A>/sequence=<S>/trial=<N>.json``, written atomically:
``{"values": [v_0, ..., v_r], "ended": bool}``. A worker needs the output folder at the runner's
path, as it does for its trajectories (``smbo.check_shared``).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from pipeline.io_utils import atomic_write_text

log = logging.getLogger(__name__)

RULE = "every earlier trial at the rung"
"""How thresholds are set, as it enters the study fingerprint (a study run under the older
rule, thresholds from the told trials only, is another study)."""

POLL_S = (0.01, 0.25)
"""First and longest pause between two reads of the posts a waiting trial needs [s]."""


@dataclass(frozen=True)
class Post:
    """One trial's posted values at the rungs it reached, and whether it runs no further."""

    values: tuple[float, ...]
    ended: bool


def rung_threshold(values: Iterable[float], eta: int) -> float | None:
    """The threshold of successive halving at a rung from the ``values`` earlier trials had
    there: a value goes on when it is among the best ``1 / eta`` of them and itself, i.e. at
    most the ((|V| + 1) // eta)-th smallest of V (at least the smallest; Optuna's rule); None
    when no finite value is given (the trial goes on)."""
    ranked = sorted(v for v in values if math.isfinite(v))
    if not ranked:
        return None
    return ranked[max((len(ranked) + 1) // eta - 1, 0)]


@dataclass(frozen=True)
class RungBoard:
    """The posts of one study (plain data, picklable: it travels in every ``TrialJob``)."""

    folder: str

    def path(self, trial: int) -> Path:
        return Path(self.folder) / f"trial={trial}.json"

    def post(self, trial: int, values: Sequence[float], ended: bool = False) -> None:
        """Post ``trial``'s values at the rungs it reached so far (atomically)."""
        Path(self.folder).mkdir(parents=True, exist_ok=True)
        text = json.dumps({"values": [float(v) for v in values], "ended": bool(ended)})
        atomic_write_text(self.path(trial), text)

    def read(self, trial: int) -> Post | None:
        """``trial``'s post; None when it has posted nothing."""
        try:
            data = json.loads(self.path(trial).read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        return Post(tuple(float(v) for v in data["values"]), bool(data["ended"]))

    def end(self, trial: int, values: Sequence[float] | None = None) -> None:
        """Mark ``trial`` as running no further, with ``values`` (None: the posted ones)."""
        if values is None:
            posted = self.read(trial)
            values = posted.values if posted is not None else ()
        self.post(trial, values, ended=True)

    def keep(self, finished: Mapping[int, Sequence[float]]) -> None:
        """Before a (resumed) run: the posts of the ``finished`` trials ({trial: curve}) stay,
        missing ones are written ended with their curve; every other post goes (those trials
        run again and post anew)."""
        folder = Path(self.folder)
        if folder.is_dir():
            for path in folder.glob("trial=*.json"):
                tid = path.stem.removeprefix("trial=")
                if not tid.isdigit() or int(tid) not in finished:
                    path.unlink(missing_ok=True)
        for trial, curve in finished.items():
            if self.read(trial) is None:
                self.end(trial, curve)

    def clear(self, trial: int) -> None:
        """Remove ``trial``'s post (it runs again)."""
        self.path(trial).unlink(missing_ok=True)

    def threshold(self, trial: int, rung: int, eta: int, wait_limit_s: float | None = None,
                  on_wait: Callable[[float], None] | None = None) -> float | None:
        """``rung_threshold`` at ``rung`` for ``trial`` over the values of trials
        0..trial-1 there, waiting until each has posted a value at the rung or ended
        (module docstring). ``on_wait(seconds)`` is told of every pause as it ends (a trial
        server's time limit leaves the waits out)."""
        values: list[float] = []
        pending = list(range(trial))
        t0 = time.monotonic()
        pause = POLL_S[0]
        while True:
            still = []
            for k in pending:
                post = self.read(k)
                if post is not None and len(post.values) > rung:
                    values.append(post.values[rung])
                elif post is None or not post.ended:
                    still.append(k)
            pending = still
            waited = time.monotonic() - t0
            if not pending:
                break
            if wait_limit_s is not None and waited > wait_limit_s:
                log.warning("trial %d at rung %d: trials %s did not reach it in %.0f s; ranked "
                            "without them", trial, rung, pending, waited)
                break
            t1 = time.monotonic()
            time.sleep(pause)
            if on_wait is not None:
                on_wait(time.monotonic() - t1)
            pause = min(2 * pause, POLL_S[1])
        return rung_threshold(values, eta)
