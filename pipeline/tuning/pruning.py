"""Stop trials early at checkpoints (docs/design.md, "Stages"): successive halving over rungs
(``trials.fidelity: halving``; Optuna's ``SuccessiveHalvingPruner``, the asynchronous
successive halving of Li et al.) or a percentile pruner over the running RTE (``trials.pruning``;
Optuna's ``PercentilePruner``).

A study's trial runs its sequences (one, or all of a joint study) and passes *checkpoints* in
order. A checkpoint says how far every sequence has run by then: ``Checkpoint.frames[s]`` is
the last frame of sequence s run (-1: not started). A trial's *value* there is the mean over
the started sequences of their *running* RTE: the mean translational RTE [%] over the segments
of length L that end at or before that frame (a finished sequence: its whole RTE), each
sequence at its own L (``Lengths``: one for all, or one a sequence); NaN as long
as a started sequence has no such segment, except at the rungs, where the mean is over the
sequences that have one (a short sequence of a joint study does not blank a rung). Its *curve*
is its values at every checkpoint it reached.

Rungs (successive halving): checkpoint r lets every sequence run to the fraction eta^(r+1-rungs)
of its frames (r = 0 .. rungs - 2; the last rung is the whole sequence), all sequences side by
side, so that a joint trial is compared on every sequence from its first rung on; with
``halving.unit: sequence`` checkpoint r runs whole sequences instead, a subset spread over the
study's holding that fraction of its frames (``sequence_rungs``: a joint trial is ranked on
whole-sequence RTEs, as at the end). At a rung, trial t posts its value and waits for every
earlier trial 0..t-1 to post there or end (``pipeline.tuning.rung_board``: the threshold
depends on trial ids, not on timing, for any number of workers): with V their values at the
rung, the trial goes on when its own value is among the best 1 / eta of V and itself (Optuna's
rule: the (|V|+1)//eta-th smallest, at least the smallest), else it stops there. The search
is told a stopped trial's failure (the penalty, ``told_loss``): TPE's good set holds whole
trials only, and the RTE of a prefix is never ranked against a whole sequence's.

Percentile: ``checkpoints - 1`` evenly spaced frames of each sequence, the sequences one after
another (a joint study also checks at the end of every sequence but the last); the threshold
is the ``percentile``-th percentile of the told *ok* trials' values there, once ``min_trials``
of them have one and from a ``warmup`` fraction of the first sequence's frames on. The search
is told a stopped trial's value.

A trial whose value is above the threshold at a checkpoint stops there: it is *pruned*. Its
objective (what the trials table holds) is its value at that checkpoint; the trajectories it
ran so far are written, so the per-frame rows it earned stay. A NaN value (no segment has
ended yet) never stops a trial.

Under ``failures: sequence`` (``pipeline.tuning.job``) a sequence of a joint trial that fails
runs no further and counts at the penalty in the trial's values from the next checkpoint on
(``value_at``'s ``failed``). It writes no trajectory, so the curve a trial records is the one
its stored trajectories give back on a resume (``StudyPruner.restore``): an ok trial's counts a
failed sequence at the penalty at every checkpoint where it had started; a pruned trial's ends
before the first such checkpoint; successive halving keeps the values posted at the rungs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from pipeline.config import Section
from pipeline.tuning.rung_board import RungBoard

F64 = NDArray[np.float64]
Lengths = float | Sequence[float]
"""The RTE length L [m] of a study's sequences: one for all of them, or one a sequence."""
Fidelity = Literal["whole", "halving"]
"""How long a study's trials run: ``whole`` (every frame of every sequence, the paper; the
percentile pruner may stop them) or ``halving`` (rungs: successive halving)."""


class PruningSection(Section):
    """params.yaml ``trials.pruning``: the percentile pruner (``percentile: null`` = off, the
    default; ``fixed.pruning`` turns it on for the joint study)."""

    percentile: float | None = Field(None, gt=0, lt=100)
    checkpoints: int = Field(10, ge=2, le=1000)
    warmup: float = Field(0.2, ge=0, lt=1)
    min_trials: int = Field(5, ge=1)


RungUnit = Literal["prefix", "sequence"]
"""What a rung of successive halving runs: a ``prefix`` of every sequence, or whole
``sequence``s, a subset spread over the study's (``sequence_rungs``)."""


class HalvingSection(Section):
    """params.yaml ``trials.halving``: the rungs of ``fidelity: halving``.

    eta: about one in eta of a rung's trials runs on to the next (Optuna's
    ``reduction_factor``); rungs: how many fidelities, the last the whole study: the first
    runs eta^-(rungs - 1) of the frames (4 and 3: 1/16, 1/4, all; eta 4 was chosen over 3 on
    reduced simulated-KITTI runs: docs/kitti.md); unit: ``prefix`` (that fraction of every
    sequence) or ``sequence`` (whole sequences holding at least that fraction of the frames,
    spread over the study's: a joint study; a study of one sequence then runs whole).
    """

    eta: int = Field(4, ge=2, le=100)
    rungs: int = Field(3, ge=2, le=10)
    unit: RungUnit = "prefix"

    def fractions(self) -> list[float]:
        """The fraction of the frames every rung but the last runs, ascending."""
        return [float(self.eta) ** (r - self.rungs + 1) for r in range(self.rungs - 1)]


@dataclass(frozen=True)
class Checkpoint:
    """How far every sequence of a study has run: ``frames[s]`` is the last frame of sequence
    s run (its count - 1 when finished, -1 when not started)."""

    frames: tuple[int, ...]


@dataclass(frozen=True)
class StoppingRule:
    """How a study stops trials: ``kind`` ("whole": never; "percentile"; "halving") and its
    settings (``pruning`` or ``halving``)."""

    kind: Literal["whole", "percentile", "halving"]
    pruning: PruningSection | None = None
    halving: HalvingSection | None = None

    @classmethod
    def of(cls, fidelity: Fidelity, pruning: PruningSection,
           halving: HalvingSection) -> StoppingRule:
        """The rule of a study with these settings: halving's rungs, else the percentile
        pruner when its percentile is set, else none."""
        if fidelity == "halving":
            return cls("halving", halving=halving)
        if pruning.percentile is not None:
            return cls("percentile", pruning=pruning)
        return cls("whole")

    @property
    def scored_only(self) -> bool:
        """Whether a value averages only the sequences on which a segment has ended (the
        rungs: a joint study's short sequences do not blank its first rung) or is NaN until
        every started one has (the percentile pruner)."""
        return self.kind == "halving"

    def describe(self) -> dict[str, Any]:
        """The rule as it enters the study fingerprint."""
        out: dict[str, Any] = {"kind": self.kind}
        for part in (self.pruning, self.halving):
            if part is not None:
                out |= part.model_dump()
        return out

    def checkpoints(self, frame_counts: Sequence[int]) -> list[Checkpoint]:
        """The checkpoints of a study over sequences of ``frame_counts`` frames, in run order."""
        if self.halving is not None:
            return rungs(frame_counts, self.halving)
        if self.pruning is not None:
            return checkpoints(frame_counts, self.pruning)
        return []

    def thresholds(self, points: Sequence[Checkpoint], frame_counts: Sequence[int],
                   reference: Sequence[Sequence[float]]) -> tuple[float | None, ...]:
        """The percentile pruner's threshold at every checkpoint (None: no check) from the
        ``reference`` curves; all None for successive halving, whose thresholds the trial
        sets at each rung (``RungBoard``)."""
        if self.pruning is not None:
            return thresholds(points, frame_counts, reference, self.pruning)
        return tuple(None for _ in points)

    def reference_curves(self, done: Mapping[int, Any], tid: int,
                         lag: int) -> list[Sequence[float]]:
        """Curves of the ok trials told to the search for ``tid`` (0..tid-lag) that set the
        percentile pruner's thresholds."""
        return [done[t].curve for t in range(tid - lag + 1)
                if t in done and done[t].status == "ok" and done[t].curve]

    def told_loss(self, status: str, objective: float, penalty_pct: float) -> float:
        """The loss TPE is told for a finished trial: its objective; a trial stopped at a rung
        counts as failed (the penalty; module docstring)."""
        return penalty_pct if self.kind == "halving" and status == "pruned" else objective


def checkpoints(frame_counts: Sequence[int], settings: PruningSection) -> list[Checkpoint]:
    """The percentile pruner's checkpoints over sequences of ``frame_counts`` frames, in run
    order (module docstring)."""
    c = settings.checkpoints
    out = []
    for s, n in enumerate(frame_counts):
        frames = sorted({max(0, math.ceil(n * i / c) - 1) for i in range(1, c)})
        if s < len(frame_counts) - 1:
            frames.append(n - 1)  # a joint study: the end of every sequence but the last
        done = tuple(m - 1 for m in frame_counts[:s])
        rest = (-1,) * (len(frame_counts) - s - 1)
        out += [Checkpoint((*done, k, *rest)) for k in frames
                if k < n - 1 or s < len(frame_counts) - 1]
    return out


def rungs(frame_counts: Sequence[int], settings: HalvingSection) -> list[Checkpoint]:
    """The rungs but the last (the whole sequences) over sequences of ``frame_counts`` frames:
    every sequence to ceil(fraction * count) - 1, side by side (``unit: sequence``:
    ``sequence_rungs``); a rung that would run no sequence further than the one before is left
    out."""
    if settings.unit == "sequence":
        return sequence_rungs(frame_counts, settings.fractions())
    out: list[Checkpoint] = []
    for fraction in settings.fractions():
        frames = tuple(min(max(0, math.ceil(n * fraction) - 1), n - 1) for n in frame_counts)
        if frames == tuple(n - 1 for n in frame_counts) or (out and frames == out[-1].frames):
            continue
        out.append(Checkpoint(frames))
    return out


def spread_order(n: int) -> list[int]:
    """0..n-1 in van der Corput order (the base-2 radical inverse of 0, 1, 2, ... scaled to n,
    repeats skipped): each prefix of the order is spread over the range, 8 -> 0 4 2 6 1 5 3 7,
    so a study whose index groups its sequences by environment meets every group early."""
    out: dict[int, None] = {}  # insertion-ordered, each index once
    j = 0
    while len(out) < n:
        v, f, i = 0.0, 0.5, j
        while i:
            v += f * (i & 1)
            i >>= 1
            f /= 2
        out.setdefault(int(v * n))
        j += 1
    return list(out)


def sequence_rungs(frame_counts: Sequence[int], fractions: Sequence[float]) -> list[Checkpoint]:
    """Rungs of whole sequences (``HalvingSection.unit: sequence``): rung r runs the first m_r
    sequences of ``spread_order`` to their ends, m_r the fewest holding ``fractions[r]`` of all
    frames (at least one); a rung with every sequence, or no more than the rung before, is
    left out. A rung's value is then the mean whole-sequence RTE of its sequences: it ranks
    parameters as the whole study does, where a prefix ranks them on a sequence's start."""
    order = spread_order(len(frame_counts))
    total = sum(frame_counts)
    out: list[Checkpoint] = []
    taken = 0
    for fraction in fractions:
        m, held = 0, 0
        while m < len(order) and (m == 0 or held < fraction * total):
            held += frame_counts[order[m]]
            m += 1
        if m >= len(order) or m <= taken:
            continue
        taken = m
        chosen = set(order[:m])
        out.append(Checkpoint(tuple(n - 1 if s in chosen else -1
                                    for s, n in enumerate(frame_counts))))
    return out


def thresholds(points: Sequence[Checkpoint], frame_counts: Sequence[int],
               reference: Sequence[Sequence[float]], settings: PruningSection
               ) -> tuple[float | None, ...]:
    """The percentile pruner's threshold at every checkpoint (None: no check there) from the
    ``reference`` curves (the told ok trials')."""
    if settings.percentile is None:
        return tuple(None for _ in points)
    out: list[float | None] = []
    for i, point in enumerate(points):
        warm = (len(point.frames) > 1 and point.frames[1] >= 0) or \
            (point.frames[0] + 1) >= settings.warmup * frame_counts[0]
        values = [float(curve[i]) for curve in reference
                  if len(curve) > i and math.isfinite(curve[i])]
        if warm and len(values) >= settings.min_trials:
            out.append(float(np.percentile(values, settings.percentile)))
        else:
            out.append(None)
    return tuple(out)


def running_rte(gt: F64, est: F64, frame: int, length_m: float) -> float:
    """Mean translational RTE [%] of the segments of ``length_m`` that end at or before
    ``frame`` (NaN when none does); ``gt``, ``est``: (N, 4, 4) T_world_lidar, N > frame."""
    from pipeline.metrics.rte import per_frame_rte

    t_err, _ = per_frame_rte(gt[:frame + 1], est[:frame + 1], length_m)
    valid = t_err[np.isfinite(t_err)]
    return float(valid.mean()) if len(valid) else math.nan


def per_sequence(length_m: Lengths, count: int) -> list[float]:
    """``length_m`` as one L [m] a sequence, for ``count`` sequences."""
    if isinstance(length_m, int | float):
        return [float(length_m)] * count
    if len(length_m) != count:
        raise ValueError(f"{len(length_m)} RTE lengths for {count} sequences")
    return [float(x) for x in length_m]


def value_at(point: Checkpoint, gts: Sequence[F64], ests: Sequence[F64 | None],
             length_m: Lengths, known: dict[int, float] | None = None,
             scored_only: bool = False, failed: Collection[int] = (),
             penalty_pct: float = math.nan) -> float:
    """A trial's value at ``point``: the mean of the running RTE of every started sequence
    (``ests[s]`` has run at least to ``point.frames[s]``) at its L (``length_m``: one for all,
    or one a sequence); NaN when one is NaN, or with ``scored_only`` (the rungs) the mean of
    those on which a segment has ended (NaN when none has). ``known``: values of finished
    sequences already computed, by sequence, filled in. ``failed``: sequences (indices) that
    count at ``penalty_pct`` [%] wherever started, their ``ests`` unread (a joint trial under
    ``failures: sequence``, ``pipeline.tuning.job``)."""
    lengths = per_sequence(length_m, len(point.frames))
    values = []
    for s, frame in enumerate(point.frames):
        if frame < 0:
            continue
        if s in failed:
            values.append(penalty_pct)
            continue
        finished = frame == len(gts[s]) - 1
        if known is not None and finished and s in known:
            values.append(known[s])
            continue
        est = ests[s]
        assert est is not None, "the trial did not run this far"
        values.append(running_rte(gts[s], est, frame, lengths[s]))
        if known is not None and finished:
            known[s] = values[-1]
    if scored_only:
        values = [v for v in values if math.isfinite(v)]
        return float(np.mean(values)) if values else math.nan
    return float(np.mean(values)) if all(map(math.isfinite, values)) else math.nan


def reached(point: Checkpoint, ests: Sequence[F64 | None], failed: Collection[int] = ()
            ) -> bool:
    """True when the trajectories ``ests`` (partial or None) run as far as ``point`` (a
    ``failed`` sequence, by index, reaches every point)."""
    return all(frame < 0 or s in failed or (est is not None and len(est) > frame)
               for s, (frame, est) in enumerate(zip(point.frames, ests, strict=True)))


def curve_of(points: Sequence[Checkpoint], gts: Sequence[F64], ests: Sequence[F64 | None],
             length_m: Lengths, scored_only: bool = False, failed: Collection[int] = (),
             penalty_pct: float = math.nan) -> tuple[float, ...]:
    """Values at ``points`` of a trial whose trajectory of sequence s is ``ests[s]`` (possibly
    partial: frames 0..len-1; None when not run); stops at the first point not reached.
    ``scored_only``, ``failed``, ``penalty_pct``: as ``value_at``."""
    known: dict[int, float] = {}
    out = []
    for point in points:
        if not reached(point, ests, failed):
            break
        out.append(value_at(point, gts, ests, length_m, known, scored_only, failed,
                            penalty_pct))
    return tuple(out)


class Pruned(Exception):  # noqa: N818 - control flow inside a trial, never shown
    """Raised inside a trial at the checkpoint where it stops."""

    def __init__(self, index: int, value: float, threshold: float) -> None:
        super().__init__(f"value {value:.4g} above {threshold:.4g}")
        self.index = index
        self.value = value
        self.threshold = threshold


class StudyPruner:
    """The stopping rule of one study: its checkpoints over the study's sequences (ground
    truths ``gts``), the curves of trials an earlier run finished, and each new trial's
    thresholds. It reads and writes nothing: the study hands it the ground truths, their L
    (``length_m``: one for all, or one a sequence) and the stored trajectories.
    ``failed_at_pct``: the penalty [%] of a study under ``failures: sequence``, whose ok trials
    count a sequence with no stored trajectory (it failed) at it; None under ``failures:
    trial``."""

    def __init__(self, gts: Sequence[F64], rule: StoppingRule, length_m: Lengths,
                 failed_at_pct: float | None = None) -> None:
        self.rule = rule
        self.length_m = length_m
        self.failed_at_pct = failed_at_pct
        self.gts = list(gts) if rule.kind != "whole" else []
        self.points = rule.checkpoints([len(g) for g in self.gts])

    @property
    def active(self) -> bool:
        """True when the study stops trials early."""
        return bool(self.points)

    def restore(self, results: Mapping[int, Any],
                trajectories: Callable[[int], list[F64 | None]]) -> dict[int, Any]:
        """``results`` (TrialResult read from the table) with the curves of their stored
        trajectories (``trajectories(trial)``: per sequence T_world_lidar, partial for a pruned
        trial, None where not run; with ``failed_at_pct``, None in an ok trial: it failed)."""
        from dataclasses import replace

        if not self.points:
            return dict(results)
        out = {}
        for tid, r in results.items():
            if r.status in ("ok", "pruned"):
                ests = trajectories(tid)
                if self.failed_at_pct is None or r.status != "ok":
                    curve = curve_of(self.points, self.gts, ests, self.length_m,
                                     self.rule.scored_only)
                else:
                    curve = curve_of(self.points, self.gts, ests, self.length_m,
                                     self.rule.scored_only,
                                     [s for s, est in enumerate(ests) if est is None],
                                     self.failed_at_pct)
                r = replace(r, curve=curve)
            out[tid] = r
        return out

    def job_fields(self, tid: int, done: Mapping[int, Any], lag: int,
                   board: RungBoard | None = None) -> dict[str, Any]:
        """``checkpoints`` and ``thresholds`` of the TrialJob of trial ``tid``; successive
        halving: the study's rung ``board`` and eta instead of thresholds."""
        if not self.points:
            return {}
        fields = {"checkpoints": tuple(p.frames for p in self.points),
                  "scored_only": self.rule.scored_only}
        if self.rule.halving is not None:  # thresholds set at the rungs, from the board
            if board is None:
                raise ValueError("successive halving needs the study's rung board")
            return fields | {"thresholds": tuple(None for _ in self.points), "rungs": board,
                             "eta": self.rule.halving.eta}
        limits = self.rule.thresholds(self.points, [len(g) for g in self.gts],
                                      self.rule.reference_curves(done, tid, lag))
        return fields | {"thresholds": limits}
