"""The SMBO trial runner: hyperopt TPE proposals, W trials in flight, resumable.

``run_trials`` is the library entry point of the ``trials`` / ``fixed`` stages: one study per
sequence (``joint=False``) or one study whose objective is the mean over all sequences
(``joint=True``, sequence ``__joint__``). Each study:
1. reads its trials table (finished trials of an earlier, killed run) into the TPE history;
2. keeps up to ``workers`` trials in flight: trial 0 is the baseline (the space's defaults),
   every other trial t is ``TpeSearch.ask`` over exactly the finished trials 0..t-lag and the
   trials t-lag+1..t-1 as pending (``told_lag``): the same history whatever order the trials
   finish in, and whether the run was killed and resumed in between, so runs with the same
   seed and workers propose the same parameters;
3. after every finished trial rewrites the trials table atomically, so a kill loses at most the
   trials in flight, and a restart runs exactly the missing trial ids 0..iterations-1.

Where the studies run (``drive``): one after another on one pool of W workers, or, on a
process pool opened here with several studies and no halving, side by side (``side_by_side``):
W single-process pools, each running one study at a time, the largest first, a pool left
without a study taking trials of the last ones. The trials and their results are the same
either way (docs/design.md, "Trials").

Failures: a trial whose odometry fails is *failed* and scored with the penalty. A trial the
machinery lost (its process killed from outside, a broken executor) is run again, up to
``retries`` times; after that it is stored as *lost*, the study stops proposing, and the run
ends with an InfrastructureError once the other studies are done; a resume runs it again.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.errors import ConfigError, InfrastructureError
from pipeline.executor import open_executor
from pipeline.io_utils import exclusive_folder
from pipeline.odometry.base import Adapter, Params, with_space
from pipeline.tuning.fingerprint import check_fingerprint, study_fingerprint
from pipeline.tuning.job import TrialJob, TrialResult, one_line
from pipeline.tuning.layout import read_trial_trajectories, rungs_folder
from pipeline.tuning.progress import StudyProgress
from pipeline.tuning.pruning import StudyPruner
from pipeline.tuning.rung_board import RULE, RungBoard
from pipeline.tuning.section import TrialsSection
from pipeline.tuning.table import JOINT, read_study, read_trials, trials_path, write_trials
from pipeline.tuning.tpe import TpeSearch, trial_seed
from pipeline.tuning.worker import run_trial

log = logging.getLogger(__name__)


@dataclass
class StudySummary:
    """What one study ended with."""

    algorithm: str
    sequence: str
    trials: int
    failed: int
    ran: int
    best_trial: int
    best_objective: float
    best_params: Params = field(default_factory=dict)
    trials_path: Path | None = None
    pruned: int = 0
    lost: list[TrialResult] = field(default_factory=list)
    wall_time_s: float = 0.0
    """Wall time [s] of the trials run now, summed (a resumed study's earlier trials were timed
    by the run that ran them: the trials table keeps no time)."""

    def record(self) -> dict[str, Any]:
        """The study in the trials stage's record (``records/<stage>.json``): counts, the best
        trial, and the wall time of the trials run now."""
        return {"algorithm": self.algorithm, "sequence": self.sequence, "trials": self.trials,
                "ran": self.ran, "failed": self.failed, "pruned": self.pruned,
                "lost": len(self.lost), "best_trial": self.best_trial,
                "best_objective": self.best_objective, "wall_time_s": self.wall_time_s}


@dataclass(frozen=True)
class Study:
    """One SMBO: a name (sequence or ``__joint__``), the sequences its objective averages,
    their own RTE lengths [m] (``SequenceInfo.length_m``: None, or () for all, where a
    sequence has none and is scored at the settings' ``length_m``) and their own jump limits
    [m] (``SequenceInfo.jump_limit_m``, likewise over the settings' ``jump_limit_m``)."""

    name: str
    sequences: tuple[tuple[str, str], ...]
    own_lengths_m: tuple[float | None, ...] = ()
    own_jump_limits_m: tuple[float | None, ...] = ()

    def lengths_m(self, default_m: float) -> tuple[float, ...]:
        """The L [m] every sequence is scored at: its own, else ``default_m``
        (base.length_m: docs/design.md, "Stages")."""
        from pipeline.sequence import scored_length_m

        own = self.own_lengths_m or (None,) * len(self.sequences)
        return tuple(scored_length_m(x, default_m) for x in own)

    def jump_limits_m(self, default_m: float) -> tuple[float, ...]:
        """The jump limit [m] a trial's trajectory of every sequence is checked at: its own,
        else ``default_m`` (trials.jump_limit_m)."""
        own = self.own_jump_limits_m or (None,) * len(self.sequences)
        return tuple(default_m if x is None else x for x in own)


def run_trials(sequence_paths: Sequence[str | Path], out_dir: str | Path, settings: TrialsSection,
               seed: int, joint: bool = False, progress: bool = True,
               on_trial: Callable[[Study, TrialResult], None] | None = None,
               executor: Executor | None = None,
               warm_start: Sequence[Params] = ()) -> list[StudySummary]:
    """Run the SMBO studies of ``sequence_paths`` into ``out_dir`` (docs/design.md, "Formats").

    ``executor``: run trials there instead of opening one from ``settings`` (left open).
    ``warm_start``: parameters every study tries first, after its baseline (trials 1..n; e.g.
    the predicted best ones for the joint study: ``warm_start.warm_start_params``).
    ``on_trial(study, result)`` is called after each finished trial is saved.
    Several studies on a process pool of its own run side by side (``side_by_side``).
    InfrastructureError when trials were lost beyond ``settings.retries`` (all others saved).
    """
    adapter = study_adapter(settings)
    studies = make_studies(sequence_paths, joint)
    for study in studies:
        for (_, path), length_m in zip(study.sequences, study.lengths_m(settings.length_m),
                                       strict=True):
            check_scorable(path, length_m)
    lanes = side_by_side(settings, len(studies), executor)
    order = costliest_studies(studies) if lanes > 1 else studies
    with exclusive_folder(out_dir, "another adaptune trials"), contextlib.ExitStack() as stack:
        pools = [stack.enter_context(TrialExecutor(settings, executor, workers=1 if lanes > 1
                                                   else None)) for _ in range(lanes)]
        waits = settings.stopping.kind == "halving" and settings.time_limit_s is None
        check_shared(pools[0].executor, [p for s in studies for _, p in s.sequences], out_dir,
                     settings.workers if waits else 0)
        runs = [functools.partial(StudyRun, study, adapter, Path(out_dir), settings, seed,
                                  progress, on_trial, warm_start) for study in order]
        done = dict(zip([s.name for s in order], drive(runs, pools), strict=True))
    summaries = [done[s.name] for s in studies]
    lost = [(s, r) for s in summaries for r in s.lost]
    if lost:
        s, r = lost[0]
        raise InfrastructureError(
            f"{len(lost)} trial(s) lost after {settings.retries} retries, e.g. {s.algorithm} "
            f"{s.sequence} trial {r.trial}: {r.error}; finished trials are saved, run again to "
            "resume")
    return summaries


def side_by_side(settings: TrialsSection, studies: int, executor: Executor | None) -> int:
    """How many studies run at once: ``settings.workers`` on a process pool opened here (one
    single-process pool a study, ``drive``'s lanes) when there are several studies and no
    successive halving, else 1 (the studies one after another on the W workers of one pool).

    Why: a worker decodes and warms the sequences of every study it runs a trial of (a tuning
    suite's HDL-64E world: 5-10 s), so on one shared pool every worker warms every study, and
    the told lag idles a worker when a trial is slower than the ones after it. Side by side
    each study is warmed once and its trials run back to back; the trials, their proposals
    and their results are the same (``told_lag`` is the settings' own). Not with halving: a
    trial waits at its rung for the study's other trials in flight, which would queue behind
    it on the same worker."""
    if executor is not None or settings.dask is not None or settings.stopping.kind == "halving":
        return 1
    return max(1, min(settings.workers, studies))


def costliest_studies(studies: Sequence[Study]) -> list[Study]:
    """``studies``, the largest first by the decoded size of their sequences (what a trial's
    odometry goes through), so that the last study to start is a small one (LPT order)."""
    from pipeline.tuning.worker import decoded_bytes

    size = {s.name: sum(decoded_bytes(p) for _, p in s.sequences) for s in studies}
    return sorted(studies, key=lambda s: -size[s.name])


def drive(runs: Sequence[Callable[[], StudyRun]], pools: Sequence[TrialExecutor]
          ) -> list[StudySummary]:
    """Run the studies ``runs`` makes (in order; each made when it starts) on ``pools`` and
    return their summaries in that order.

    Each pool (a lane) runs one study at a time, its home: one lane (a pool of W workers) runs
    the studies one after another with W trials in flight. With several lanes (one worker
    each), a lane whose study is over takes the next; with none left, it takes the trials of
    running studies whose home lane is busy, so the last study does not run on one worker
    alone."""
    pending = list(enumerate(runs))[::-1]
    home: dict[int, tuple[int, StudyRun]] = {}  # lane -> (index of the study, the study)
    lanes = _Lanes(pools)
    summaries: dict[int, StudySummary] = {}
    try:
        while pending or home:
            for lane in range(len(pools)):
                if lane not in home and pending:
                    i, make = pending.pop()
                    home[lane] = (i, make().start())
            for lane, (i, run) in sorted(home.items(), key=lambda kv: kv[1][0]):
                while run.can_start():
                    lanes.submit(lanes.place(lane, home), i, run, run.next_job())
            for lane, (i, run) in list(home.items()):
                if run.over():  # its progress ends now, its summary is kept
                    del home[lane]
                    run.close()
                    summaries[i] = run.summary()
            for at, i, run, job, result in lanes.finished():
                if run.finish(job, result):  # lost: again, on the same lane
                    lanes.submit(at, i, run, job)
    finally:  # an error or Ctrl-C: the progress of the studies still running ends too
        for _, run in home.values():
            run.close()
    return [summaries[i] for i in range(len(runs))]


class _Lanes:
    """The pools of ``drive`` and the trials in flight on each."""

    def __init__(self, pools: Sequence[TrialExecutor]) -> None:
        self.pools = pools
        self.load = [0] * len(pools)
        self.in_flight: dict[Future[TrialResult], tuple[int, int, StudyRun, TrialJob]] = {}

    def place(self, lane: int, home: Mapping[int, Any]) -> int:
        """Where a trial of the study at home on ``lane`` runs: there, unless its worker is
        busy and a lane with no study of its own is idle (several single-worker lanes)."""
        if len(self.pools) == 1 or self.load[lane] == 0:
            return lane
        idle = [k for k in range(len(self.load)) if k not in home and self.load[k] == 0]
        return idle[0] if idle else lane

    def submit(self, at: int, i: int, run: StudyRun, job: TrialJob) -> None:
        """Run ``job`` of study ``i`` (``run``) on lane ``at``."""
        self.in_flight[self.pools[at].submit(job)] = (at, i, run, job)
        self.load[at] += 1

    def finished(self) -> list[tuple[int, int, StudyRun, TrialJob, TrialResult]]:
        """The trials that finish next (waiting for at least one; none when none is in
        flight): (lane, study index, study, job, result), by study index and trial."""
        if not self.in_flight:
            return []
        done, _ = wait(self.in_flight, return_when=FIRST_COMPLETED)
        out = []
        for fut in done:
            at, i, run, job = self.in_flight.pop(fut)
            self.load[at] -= 1
            out.append((at, i, run, job, _result_of(fut, job)))
        return sorted(out, key=lambda x: (x[1], x[3].trial))


class StudyRun:
    """One study (or its resumption) as ``drive`` runs it: which trial may start
    (``can_start``, ``next_job``), what a finished one changes (``finish``), when it is over and
    its summary. Its progress is shown from ``start`` to ``close``.

    Up to ``settings.workers`` trials are in flight; trial t starts once trials 0..t-lag are
    finished (``told_lag``) and is proposed from exactly those, so where and in which order
    its trials run changes nothing. A lost trial runs again up to ``settings.retries`` times;
    after that the study stops starting trials."""

    def __init__(self, study: Study, adapter: Adapter, out_dir: Path, settings: TrialsSection,
                 seed: int, progress: bool = True,
                 on_trial: Callable[[Study, TrialResult], None] | None = None,
                 warm_start: Sequence[Params] = ()) -> None:
        space = adapter.space
        self.study, self.adapter, self.out_dir = study, adapter, out_dir
        self.settings, self.seed, self.on_trial = settings, seed, on_trial
        self.table = trials_path(out_dir, adapter.name, study.name)
        self.first = [space.validate(p) for p in warm_start]
        stored_study = read_study(self.table)
        self.fingerprint = study_of(study, adapter, settings, seed, warm_start=self.first)
        if self.table.is_file():
            check_fingerprint(stored_study, self.fingerprint, str(self.table))
        stored = [r for r in read_trials(self.table, space) if r.trial < settings.iterations]
        self.pruner = study_pruner(study, settings)
        self.done = self.pruner.restore(
            {r.trial: r for r in stored if r.status != "lost"},
            lambda tid: read_trial_trajectories(out_dir, adapter.name, study.sequences, tid))
        self.lost: dict[int, TrialResult] = {}
        self.proposed = {t: r.params for t, r in self.done.items()}
        self.todo = [t for t in range(settings.iterations) if t not in self.done]
        self.ran = 0
        self.running = 0
        self.attempts: dict[int, int] = {}
        if self.done:
            log.info("%s %s: resuming, %d of %d trials finished", adapter.name, study.name,
                     len(self.done), settings.iterations)
        self.lag = told_lag(settings.workers)
        self.search = TpeSearch(space, seed, settings.startup_trials)
        self.board = study_board(self.pruner, out_dir, adapter.name, study.name, self.done)
        self.shown = StudyProgress(f"trials {adapter.name} {study.name}", settings.iterations,
                                   len(self.done), progress)

    def start(self) -> StudyRun:
        """Show the study's progress (a bar, or its first line); returns the study."""
        self.shown.__enter__()
        return self

    def close(self) -> None:
        """End the study's progress (its last line)."""
        self.shown.__exit__(None, None, None)

    def can_start(self) -> bool:
        """Whether the next trial may start now."""
        return bool(self.todo and not self.lost and self.running < self.settings.workers
                    and all(t in self.done for t in range(self.todo[0] - self.lag + 1)))

    def next_job(self) -> TrialJob:
        """The job of the next trial (proposed now), counted as running."""
        tid = self.todo.pop(0)
        self.proposed[tid] = (self.first[tid - 1] if 0 < tid <= len(self.first)
                              else propose(self.search, tid, self.done, self.proposed, self.lag,
                                           self._told_loss))
        self.running += 1
        return make_job(self.study, self.adapter, tid, trial_seed(self.seed, tid),
                        self.proposed[tid], self.out_dir, self.settings,
                        **self.pruner.job_fields(tid, self.done, self.lag, self.board))

    def _told_loss(self, r: TrialResult) -> float:
        return self.pruner.rule.told_loss(r.status, r.objective, self.settings.penalty_pct)

    def finish(self, job: TrialJob, result: TrialResult) -> bool:
        """Record the ``result`` of ``job`` (saved in the trials table); True when the job is
        to run again (lost, within its retries: it counts as running still)."""
        if result.status == "lost":
            self.attempts[job.trial] = self.attempts.get(job.trial, 0) + 1
            if self.attempts[job.trial] <= self.settings.retries:
                log.warning("%s %s trial %d lost (%s); running it again", self.adapter.name,
                            self.study.name, job.trial, result.error)
                if self.board is not None:
                    self.board.clear(job.trial)
                return True
            self.lost[job.trial] = result
            if self.board is not None:  # later trials stop waiting for it
                self.board.end(job.trial)
        else:
            self.done[job.trial] = result
        self.running -= 1
        write_trials(self.table, self.adapter.space, [*self.done.values(), *self.lost.values()],
                     self.fingerprint)
        self.ran += 1
        self.shown.update({**self.done, **self.lost})
        if result.status == "failed":
            log.debug("trial %d failed: %s", result.trial, result.error)
        if self.on_trial is not None:
            self.on_trial(self.study, result)
        return False

    def over(self) -> bool:
        """Nothing running and nothing that may start: every trial finished, or one lost."""
        return not self.running and not self.can_start()

    def summary(self) -> StudySummary:
        """Counts, the best trial and the lost trials."""
        summary = summarize(self.adapter.name, self.study.name, self.done, self.ran, self.table)
        summary.lost = sorted(self.lost.values(), key=lambda r: r.trial)
        return summary


def study_adapter(settings: TrialsSection) -> Adapter:
    """The adapter of ``settings`` searching its space with ``settings.space`` applied."""
    from pipeline.odometry.registry import build_adapter

    adapter = build_adapter(settings.algorithm, settings.adapter_options)
    if not settings.space:
        return adapter
    changes = {name: r.model_dump(exclude_none=True) for name, r in settings.space.items()}
    return with_space(adapter, adapter.space.override(changes, "trials.space"))


def make_studies(sequence_paths: Sequence[str | Path], joint: bool) -> list[Study]:
    """One study per sequence (named by file stem), or one joint study over all of them, each
    with its sequences' own RTE lengths and jump limits (their metadata read)."""
    if not sequence_paths:
        raise ConfigError("no sequences given")
    named = [(Path(p).stem, str(p)) for p in sequence_paths]
    stems = [n for n, _ in named]
    dup = sorted({n for n in stems if stems.count(n) > 1})
    if dup:
        raise ConfigError(f"sequence names must be unique (file stems), {dup[0]!r} is given twice")
    if JOINT in stems:
        raise ConfigError(f"{JOINT!r} is reserved for the joint study")
    from pipeline.sequence import read_info

    infos = {p: read_info(p) for _, p in named}
    groups = [named] if joint else [[one] for one in named]
    return [Study(JOINT if joint else group[0][0], tuple(group),
                  tuple(infos[p].length_m for _, p in group),
                  tuple(infos[p].jump_limit_m for _, p in group)) for group in groups]


def study_pruner(study: Study, settings: TrialsSection) -> StudyPruner:
    """The study's stopping rule, with its sequences' ground truths when it stops trials (and
    the penalty a failed sequence counts at, under ``failures: sequence``)."""
    from pipeline.sequence import read_ground_truth
    from pipeline.tuning.job import TRIALS_PURPOSE

    rule = settings.stopping
    on = rule.kind != "whole"
    gts = [read_ground_truth(path, TRIALS_PURPOSE) for _, path in study.sequences] if on else []
    failed_at = settings.penalty_pct if settings.failures == "sequence" else None
    return StudyPruner(gts, rule, study.lengths_m(settings.length_m), failed_at)


def check_scorable(path: str | Path, length_m: float) -> None:
    """InputError unless the sequence has ground truth longer than ``length_m`` (RTE needs it)."""
    from pipeline.metrics.rte import check_scorable as check_ground_truth
    from pipeline.sequence import read_ground_truth
    from pipeline.tuning.job import TRIALS_PURPOSE

    check_ground_truth(read_ground_truth(path, TRIALS_PURPOSE), length_m, str(path))


def study_board(pruner: StudyPruner, out_dir: Path, algorithm: str, study: str,
                done: dict[int, TrialResult]) -> RungBoard | None:
    """The rung board of a study of successive halving (None for any other), with the posts of
    its ``done`` trials only (``RungBoard.keep``: those of trials a killed run left unfinished
    go, they run again)."""
    if pruner.rule.kind != "halving" or not pruner.active:  # no rung: the trials run whole
        return None
    board = RungBoard(str(rungs_folder(out_dir, algorithm, study)))
    board.keep({t: r.curve for t, r in done.items()})
    return board


def study_of(study: Study, adapter: Adapter, settings: TrialsSection, seed: int,
             warm_start: Sequence[Params] = ()) -> dict[str, Any]:
    """The fingerprint of ``study`` run with ``settings`` (``pipeline.tuning.fingerprint``)."""
    return study_fingerprint(
        adapter=settings.algorithm, adapter_options=settings.adapter_options,
        space=adapter.space.to_json(), seed=seed, length_m=settings.length_m,
        penalty_pct=settings.penalty_pct, jump_limit_m=settings.jump_limit_m,
        time_limit_s=settings.time_limit_s, startup_trials=settings.startup_trials,
        told_lag=told_lag(settings.workers), pruning=settings.pruning.model_dump(),
        fidelity=(settings.halving.model_dump() | {"thresholds": RULE}
                  if settings.fidelity == "halving" else None),
        warm_start=[dict(p) for p in warm_start], sequences=list(study.sequences),
        own_lengths_m=list(study.own_lengths_m),
        own_jump_limits_m=list(study.own_jump_limits_m), failures=settings.failures)


def told_lag(workers: int) -> int:
    """How far behind the proposal the search's history is: trial t is proposed from the
    finished trials 0..t-lag (the rest pending), whatever order the executor finishes them in,
    so that a run with W workers is as deterministic as a serial one. 1 for a serial run (the
    previous trial is always finished); 2W - 1 otherwise, so a worker idles only when one trial
    is slower than the 2W - 2 trials after it."""
    return 1 if workers == 1 else 2 * workers - 1


def propose(search: TpeSearch, tid: int, done: dict[int, TrialResult],
            proposed: dict[int, Params], lag: int,
            loss: Callable[[TrialResult], float] = lambda r: r.objective) -> Params:
    """Parameters of trial ``tid``: the baseline (defaults) for trial 0, else a TPE proposal
    from exactly the finished trials 0..tid-lag (told ``loss(result)``: the study's
    ``StoppingRule.told_loss``) and the pending tid-lag+1..tid-1 (as in an uninterrupted run,
    whatever a resumed one found finished beyond them)."""
    if tid == 0:
        return search.space.defaults()
    search.reset(told={t: (done[t].params, loss(done[t])) for t in range(tid - lag + 1)},
                 pending={t: proposed[t] for t in range(max(0, tid - lag + 1), tid)})
    return search.ask(tid)


def make_job(study: Study, adapter: Adapter, tid: int, seed: int, params: Params, out_dir: Path,
             settings: TrialsSection, **pruning: Any) -> TrialJob:
    """The picklable job of one trial (``pruning``: its checkpoints and thresholds); its paths
    are absolute, as a Dask worker started in another folder (or machine) needs them."""
    sequences = tuple((name, str(Path(path).resolve())) for name, path in study.sequences)
    return TrialJob(adapter=settings.algorithm, algorithm=adapter.name, sequences=sequences,
                    trial=tid, seed=seed, params=dict(params), out_dir=str(out_dir.resolve()),
                    length_m=settings.length_m, penalty_pct=settings.penalty_pct,
                    jump_limit_m=settings.jump_limit_m, time_limit_s=settings.time_limit_s,
                    adapter_options=dict(settings.adapter_options),
                    space=adapter.space.to_json() if settings.space else None,
                    lengths_m=study.lengths_m(settings.length_m),
                    jump_limits_m=study.jump_limits_m(settings.jump_limit_m),
                    failures=settings.failures, **pruning)


def summarize(algorithm: str, sequence: str, done: dict[int, TrialResult], ran: int,
              table: Path) -> StudySummary:
    """Counts and the best trial (lowest objective among ok trials; the baseline if none is ok)."""
    ok = [r for r in done.values() if r.status == "ok"]
    best = min(ok or done.values() or [_NO_TRIAL], key=lambda r: (r.objective, r.trial))
    failed = sum(r.status == "failed" for r in done.values())
    return StudySummary(algorithm, sequence, len(done), failed, ran, best.trial,
                        best.objective if ok else math.nan, dict(best.params), table,
                        pruned=sum(r.status == "pruned" for r in done.values()),
                        wall_time_s=math.fsum(r.wall_time_s for r in done.values()
                                              if math.isfinite(r.wall_time_s)))


_NO_TRIAL = TrialResult(-1, "lost", "", math.nan, 0.0, 0, {})


# -- executors -----------------------------------------------------------------------------

class TrialExecutor:
    """Where trials run: the given executor, or one opened from the settings, which is opened
    anew when it breaks (a process-pool worker killed: its trials come back lost and are
    retried)."""

    def __init__(self, settings: TrialsSection, executor: Executor | None = None,
                 workers: int | None = None) -> None:
        self.settings = settings
        self.given = executor
        self.workers = settings.workers if workers is None else workers
        """Processes of an opened pool (fewer than ``settings.workers`` when several pools
        run side by side: each gets ``1 / settings.workers`` of the machine)."""
        self._stack = contextlib.ExitStack()
        self.executor = executor if executor is not None else self._open()

    def _open(self) -> Executor:
        return self._stack.enter_context(open_executor(self.workers, self.settings.dask,
                                                       share=self.settings.workers))

    def submit(self, job: TrialJob) -> Future[TrialResult]:
        """``run_trial(job)`` on the executor."""
        try:
            return self.executor.submit(run_trial, job)
        except BrokenProcessPool:
            if self.given is not None:
                raise InfrastructureError("the process pool broke (a worker died); finished "
                                          "trials are saved, run again to resume") from None
            log.warning("the process pool broke (a worker died); starting a new one")
            self._stack.close()
            self._stack = contextlib.ExitStack()
            self.executor = self._open()
            return self.executor.submit(run_trial, job)

    def __enter__(self) -> TrialExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.__exit__(*exc)  # type: ignore[arg-type]


def check_shared(executor: Executor, paths: Sequence[str | Path], out_dir: str | Path,
                 at_once: int = 0) -> None:
    """ConfigError unless every worker of a Dask cluster reads ``paths`` and writes ``out_dir``
    at the same paths (workers on other machines need a shared filesystem), and has at least
    ``at_once`` threads in all (trials that wait at their rungs without a time limit)."""
    client = getattr(executor, "_client", None)
    if client is None:
        return
    threads = sum(client.nthreads().values())
    if threads < at_once:
        raise ConfigError(f"the Dask cluster runs {threads} trials at once, fewer than "
                          f"trials.workers={at_once}: successive halving without a time limit "
                          "needs every trial in flight running (set trials.time_limit_s, or "
                          "trials.workers to at most the cluster's threads)")
    wanted = [str(Path(p).resolve()) for p in paths]
    answers = client.run(_sees, wanted, str(Path(out_dir).resolve()))
    for worker, missing in sorted(answers.items()):
        if missing:
            raise ConfigError(f"Dask worker {worker} cannot reach {missing}: workers must see "
                              "the sequences and the output folder at the same paths (a "
                              "shared filesystem)")


def _sees(paths: list[str], out_dir: str) -> str:
    """On a worker: the first of ``paths`` it cannot read or ``out_dir`` if it cannot write
    there; "" when all is well."""
    for p in paths:
        if not os.access(p, os.R_OK):
            return p
    return "" if os.access(out_dir, os.W_OK) else out_dir


def _result_of(fut: Future[TrialResult], job: TrialJob) -> TrialResult:
    """The result of a finished future; a lost result when the executor itself failed (a
    worker process died, a Dask worker was lost too often)."""
    try:
        return fut.result()
    except Exception as exc:
        return TrialResult(job.trial, "lost", f"executor: {one_line(exc)}", math.nan, 0.0,
                           job.seed, dict(job.params))

