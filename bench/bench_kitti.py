"""What the full KITTI protocol costs, whole trials against successive halving (issues 15 and
33; docs/kitti.md, "What the full protocol costs").

Two measurements, one model.

1. Per-frame cost of every in-process adapter on simulated KITTI (``pipeline.sim.kitti_dataset``,
   HDL-64E, ~125k points a scan): the first FRAMES frames of one sequence per environment (07
   urban, 00 residential, 04 rural, 01 highway), each run through ``run_sequence`` as the
   evaluate stage and an uncached trial run it (MCAP decoding included), once with the
   defaults and with SAMPLES parameter sets drawn uniformly from the adapter's space; the
   sampled sets again over scans decoded once and an adapter warmed on them, as a trial runs
   when its study fits its worker's scan cache (``pipeline.tuning.worker``); and decoding
   alone. The figure is CPU time per frame (the process and its decoding thread).
2. Promotion at the rungs of successive halving (``trials.fidelity: halving`` with the params'
   ``trials.halving``): one real study of the paper's budget, 256 proposals of NDT, with 16
   workers' settings, run one trial at a time on the first HALVING_FRAMES frames of sequence
   00, L scaled so that the window is as many L long as sequence 00 is 100 m. A trial is ranked
   at a rung against every earlier trial (``pipeline.tuning.rung_board``), so the study is the
   16-worker one whatever the executor; its proposals lag ``told_lag(16)`` = 31 trials. The
   same study with one worker's settings (proposals lagging 1) is printed beside it. Measured:
   the fraction of frames its trials ran, and p_r, the fraction of the trials checked at rung r
   that went on (NDT's p_r stand for every adapter: the rule promotes the best 1/eta of the
   earlier trials, whatever the odometry); and, from its trials' frames and odometry times, the
   worker time 16 workers would spend waiting at the rungs for earlier trials
   (``rung_schedule``).

The model counts the odometry of the protocol: n_s frames of sequence s (from
``kitti_trajectories``: 23,201 frames, 14,136 in 00-05), each frame at the CPU cost of its
environment (the simulated-KITTI schedules); c = sampled parameters (a trial, the fixed and the
adaptive runs), d = the defaults (the baseline). C_s(a, b) = the cost of frames a..b-1 of s.
A study whose sequences fit one worker's scan cache (``scan_cache_limit_bytes`` of the
worker's share of the memory: MEMORY_BYTES shared by the N workers, 2 GiB each; of the full
protocol 03 and 04, ~1.5 and ~0.5 GB decoded) runs its trials at the cached cost instead, and
every worker that runs one of them decodes the sequences once.

    whole:    core-s = I * sum_s C_s(0, n_s) + J * sum_s C_s(0, n_s) + E
    halving:  core-s = I * sum_s sum_r R_s,r C_s(k_s,r-1, k_s,r) + J * sum_r R_r sum_s C_s(...) + E

k_s,r: the last frame of rung r of s (``pipeline.tuning.pruning.rungs``; k_s,-1 = 0); R_s,r:
the share of trials that run rung r, the product of p_q over the rungs q < r at which a
trial of s is checked (a rung is checked only where a segment of L = 100 m has ended, from the
ground-truth path; a joint trial's rung where one has ended on any sequence). E: the adaptive
and evaluate stages, baseline (d), fixed and adaptive (c) over all 11 sequences, each a job of
its own, ``evaluate.workers`` at a time. I = J = 256 is the paper's budget; the preset's own
(256 per sequence, 64 joint, warm-started) is given apart: a smaller budget is not a saving.

Wall time on N workers: the six per-sequence studies one after another, each with N trials in
flight, then the joint study: whole trials ceil(I / N) * C_s (waves of N), halving
m I F_s C_s / N (F_s = the study's fraction of frames; m = the measured study's makespan on N
workers over its work / N, ``rung_schedule``: the waiting at the rungs, the workers idle while
the proposals' lag holds the next trial back, and the last trials' tail); then E as
the longest processing time first schedule of its jobs on N processes (``evaluate.workers`` =
N). Left out: simulation or ingest, descriptors, RTE scoring, the surrogate and the selector
(each a single pass over the frames or less).
Environment: ADAPTUNE_BENCH_KITTI_FRAMES (default 20), ADAPTUNE_BENCH_KITTI_SAMPLES (3),
ADAPTUNE_BENCH_HALVING_FRAMES (150), ADAPTUNE_BENCH_HALVING_TRIALS (256: a smaller study is a
smoke test, not the figure).
"""

from __future__ import annotations

import heapq
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from common import Row, data_root, size

if TYPE_CHECKING:
    from pipeline.tuning.pruning import HalvingSection, RungUnit

ADAPTERS = ("gicp", "kiss_icp", "ndt")
ENVIRONMENT_SEQUENCE = {"urban": "07", "residential": "00", "rural": "04", "highway": "01"}
TRAIN = ("00", "01", "02", "03", "04", "05")
TEST = ("06", "07", "08", "09", "10")
ITERATIONS = 256
PRESET_JOINT = 64
WORKERS = 16
MEMORY_BYTES = 64 << 30
"""The workstation the full protocol is modelled on: WORKERS cores, 64 GiB."""
LENGTH_M = 100.0
HALVING_SEQUENCE = "00"


@dataclass
class Cost:
    """Seconds per frame of one adapter in one environment: CPU and wall, defaults and sampled
    read from the MCAP (``run_sequence``); ``cpu_cached``: sampled over scans decoded once and
    an adapter warmed on them (a trial whose study fits its worker's scan cache; NaN: as
    ``cpu_sampled``); ``cpu_decode``: decoding a frame; ``bytes_per_frame``: a decoded frame."""

    cpu_default: float
    wall_default: float
    cpu_sampled: float
    failed: int
    cpu_cached: float = math.nan
    cpu_decode: float = 0.0
    bytes_per_frame: float = 0.0


@dataclass
class Drive:
    """One KITTI sequence of the protocol: the environment of every frame and the path [m]."""

    environments: list[str]
    distance_m: np.ndarray

    @property
    def frames(self) -> int:
        return len(self.environments)


@dataclass
class Promotion:
    """What the halving study measured: p_r per rung, the fraction of frames run, CPU time;
    its trials scheduled on WORKERS workers (``rung_schedule``): ``waiting``, the worker time
    spent waiting at the rungs per unit of work, and ``makespan``, the schedule's length over
    the work / WORKERS (None: not measured)."""

    rates: list[float]
    fraction: float
    trials: int
    cpu_s: float
    waiting: float = 0.0
    makespan: float | None = None


def run() -> list[Row]:
    trajectories = data_root() / "kitti_trajectories"
    if not trajectories.is_dir():
        return []
    frames = int(os.environ.get("ADAPTUNE_BENCH_KITTI_FRAMES", size("20", "2")))
    samples = int(os.environ.get("ADAPTUNE_BENCH_KITTI_SAMPLES", size("3", "1")))
    halving_frames = int(os.environ.get("ADAPTUNE_BENCH_HALVING_FRAMES", size("150", "16")))
    drives = kitti_drives(trajectories)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        paths, points = simulate(trajectories, frames, Path(tmp))
        studies = {n: Path(tmp) / f"halving-{n}" for n in (WORKERS, 1)}
        for folder in studies.values():
            folder.mkdir()
        promotion = halving_promotion(trajectories, halving_frames, drives, studies[WORKERS])
        serial = halving_promotion(trajectories, halving_frames, drives, studies[1], workers=1)
        rows.append(promotion_row(promotion, halving_frames, WORKERS))
        rows.append(promotion_row(serial, halving_frames, 1))
        for name in ADAPTERS:
            costs = environment_costs(name, paths, samples)
            rows += cost_rows(name, costs, points, samples)
            rows += protocol_rows(name, costs, drives, promotion)
    return rows


def kitti_drives(trajectories: Path) -> dict[str, Drive]:
    """Sequence -> its Drive, for KITTI 00-10 (their simulated-KITTI schedules)."""
    from pipeline.geometry import path_distances
    from pipeline.sim.kitti import kitti_lidar_poses
    from pipeline.sim.kitti_world import SCHEDULES, frame_environments

    out = {}
    for seq in SCHEDULES:
        poses = kitti_lidar_poses(trajectories / f"{seq}.txt")[0]
        out[seq] = Drive(frame_environments(seq, len(poses)), path_distances(poses))
    return out


def simulate_window(trajectories: Path, seq: str, frames: int, out: Path) -> Path:
    """The first ``frames`` frames of simulated KITTI ``seq`` as an MCAP at ``out``."""
    from pipeline.sim.kitti_dataset import SimulateKittiSection, simulate_kitti_sequence

    section = SimulateKittiSection(trajectories=str(trajectories), train=[seq],
                                   windows=[(seq, 0, frames - 1)])
    return simulate_kitti_sequence(section, seq, 0, out).path


def simulate(trajectories: Path, frames: int, tmp: Path) -> tuple[dict[str, Path], dict[str, int]]:
    """The first ``frames`` frames of each environment's sequence as MCAPs; mean points a scan."""
    from pipeline.sequence import SequenceReader

    paths, points = {}, {}
    for env, seq in size(ENVIRONMENT_SEQUENCE, {"rural": "04"}).items():
        paths[env] = simulate_window(trajectories, seq, frames, tmp / f"{seq}.mcap")
        with SequenceReader(paths[env]) as reader:
            points[env] = int(np.mean([len(scan.points_lidar) for scan in reader]))
    for env in ENVIRONMENT_SEQUENCE:  # a smoke run simulates one: it stands for them all
        paths.setdefault(env, paths["rural"])
        points.setdefault(env, points["rural"])
    return paths, points


def environment_costs(name: str, paths: dict[str, Path], samples: int) -> dict[str, Cost]:
    """Environment -> ``adapter_cost`` of adapter ``name`` over that environment's sequence
    (``simulate``'s ``paths``; a sequence that stands for several is timed once)."""
    by_path = {path: adapter_cost(name, path, samples) for path in set(paths.values())}
    return {env: by_path[path] for env, path in paths.items()}


def adapter_cost(name: str, path: Path, samples: int) -> Cost:
    """Per-frame cost of adapter ``name`` over the sequence ``path`` (module docstring): read
    from the MCAP as the evaluate stage and an uncached trial run it, and over decoded scans
    as a trial of a study that fits its worker's scan cache runs it
    (``pipeline.tuning.worker``: the scans decoded once, the adapter warmed on them)."""
    from pipeline.errors import AdaptuneError
    from pipeline.odometry import get_adapter, run_scans, run_sequence
    from pipeline.sequence import SequenceReader
    from pipeline.tuning.worker import decoded_bytes

    adapter = get_adapter(name)
    cpu = time.process_time()
    with SequenceReader(path) as reader:
        scans, stamps_ns = list(reader), np.asarray(reader.stamps_ns)
    n = len(scans)
    decode = (time.process_time() - cpu) / n
    warmed = get_adapter(name)
    warm = getattr(warmed, "warm", None)
    if warm is not None:
        warm(scans)

    def timed(params: dict[str, float]) -> tuple[float, float]:
        cpu, wall = time.process_time(), time.perf_counter()
        run_sequence(adapter, path, params)
        return (time.process_time() - cpu) / n, (time.perf_counter() - wall) / n

    def timed_cached(params: dict[str, float]) -> float:
        cpu = time.process_time()
        run_scans(warmed, scans, stamps_ns, params, str(path))
        return (time.process_time() - cpu) / n

    timed(adapter.space.defaults())  # warm-up: JIT caches, imports, page cache
    cpu_default, wall_default = timed(adapter.space.defaults())
    rng = np.random.default_rng(0)
    sampled, cached, failed = [], [], 0
    for _ in range(samples):
        params = adapter.space.from_unit(rng.random(len(adapter.space.names)))
        try:
            sampled.append(timed(params)[0])
            cached.append(timed_cached(params))
        except AdaptuneError:  # a diverging trial: scored with the penalty, its time not counted
            failed += 1
    mean = (lambda xs: float(np.mean(xs)) if xs else math.nan)  # noqa: E731
    return Cost(cpu_default, wall_default, mean(sampled), failed, mean(cached), decode,
                decoded_bytes(str(path)) / n)


def cost_rows(name: str, costs: dict[str, Cost], points: dict[str, int],
              samples: int) -> list[Row]:
    rows = []
    for env, c in costs.items():
        seq = ENVIRONMENT_SEQUENCE[env]
        failed = f", {c.failed} of {samples} sampled sets failed" if c.failed else ""
        rows.append(Row(f"{name} per frame, sim. HDL-64E {env} ({seq}, {points[env] // 1000}k "
                        "pts), defaults, CPU", 1000 * c.cpu_default, "ms",
                        f"wall {1000 * c.wall_default:.0f} ms; {samples} sampled parameter "
                        f"sets: CPU {1000 * c.cpu_sampled:.0f} ms, over cached scans "
                        f"{1000 * c.cpu_cached:.0f} ms; decoding {1000 * c.cpu_decode:.1f} ms"
                        f"{failed}"))
    return rows


# -- the halving study -------------------------------------------------------------------

def halving_settings(length_m: float, halving: HalvingSection | None = None,
                     workers: int = WORKERS) -> object:
    """The measured study's TrialsSection: NDT, the paper's budget, the told lag of ``workers``
    workers, the params' halving (or ``halving``), no time limit (in the process)."""
    from pipeline.tuning.section import TrialsSection

    trials = int(os.environ.get("ADAPTUNE_BENCH_HALVING_TRIALS", size(str(ITERATIONS), "4")))
    rungs = {} if halving is None else {"halving": halving}
    return TrialsSection(algorithm="ndt", iterations=trials, workers=workers,
                         time_limit_s=None, length_m=length_m, fidelity="halving", **rungs)


def halving_promotion(trajectories: Path, frames: int, drives: dict[str, Drive],
                      tmp: Path, halving: HalvingSection | None = None,
                      workers: int = WORKERS) -> Promotion:
    """Run the halving study (module docstring, 2.) and read what it promoted; ``halving``:
    other rungs than the params', ``workers``: another told lag."""
    from concurrent.futures import ThreadPoolExecutor

    from pipeline.tuning.smbo import run_trials

    path = simulate_window(trajectories, HALVING_SEQUENCE, frames, tmp / "halving.mcap")
    drive = drives[HALVING_SEQUENCE]
    length_m = LENGTH_M * float(drive.distance_m[frames - 1]) / float(drive.distance_m[-1])
    settings = halving_settings(length_m, halving, workers)
    odometry_s: dict[int, float] = {}
    cpu = time.process_time()
    with ThreadPoolExecutor(1) as one:  # one trial at a time: the same study as 16 workers'
        run_trials([path], tmp / "trials", settings, seed=0,  # type: ignore[arg-type]
                   progress=False, executor=one,
                   on_trial=lambda _, r: odometry_s.__setitem__(r.trial, r.odometry_s))
    promotion = promotion_of(tmp / "trials", path.stem, frames, settings, odometry_s)
    promotion.cpu_s = time.process_time() - cpu
    return promotion


def promotion_of(out: Path, sequence: str, frames: int, settings: object,
                 odometry_s: dict[int, float] | None = None) -> Promotion:
    """p_r and the fraction of frames run of the study ``sequence`` in the trials folder ``out``:
    a trial's frames are its trajectory's (a failed trial's: all); the waiting at the rungs
    from every trial's ``odometry_s`` (its time in the odometry, as the study ran it; the
    trials table's wall time where not given, which counts a worker's warm-up in its first
    trial)."""
    from pipeline.trajectory import read_trajectory
    from pipeline.tuning.layout import trajectory_path
    from pipeline.tuning.pruning import rungs
    from pipeline.tuning.smbo import study_adapter, told_lag
    from pipeline.tuning.table import read_trials, trials_path

    adapter = study_adapter(settings)  # type: ignore[arg-type]
    results = read_trials(trials_path(out, adapter.name, sequence), adapter.space)
    ran = []
    for r in results:
        path = trajectory_path(out, adapter.name, sequence, r.trial)
        ran.append(len(read_trajectory(path)) if r.status == "pruned" else frames)
    ends = [p.frames[0] + 1 for p in rungs([frames], settings.halving)]  # type: ignore[attr-defined]
    reached = [sum(n >= end for n in ran) for end in ends]
    went_on = [sum(n > end for n in ran) for end in ends]
    rates = [w / r if r else 1.0 for w, r in zip(went_on, reached, strict=True)]
    spent = odometry_s or {}
    seconds = [spent.get(r.trial, r.wall_time_s) / n for r, n in zip(results, ran, strict=True)]
    schedule = rung_schedule(ran, seconds, ends, frames, WORKERS,
                             told_lag(settings.workers))  # type: ignore[attr-defined]
    return Promotion(rates, sum(ran) / (frames * len(ran)), len(ran), 0.0,
                     schedule.waiting_s / schedule.work_s,
                     schedule.makespan_s / (schedule.work_s / WORKERS))


@dataclass
class Schedule:
    """A study's trials on W workers (``rung_schedule``): how long it takes, the work in it
    and the worker time spent waiting at the rungs [s]."""

    makespan_s: float
    work_s: float
    waiting_s: float


def rung_schedule(ran: list[int], seconds_per_frame: list[float], ends: list[int], frames: int,
                  workers: int, lag: int) -> Schedule:
    """The trials of a halving study, trial t running ``ran[t]`` frames of ``frames`` at
    ``seconds_per_frame[t]``, on ``workers`` workers as the trials stage runs them
    (``pipeline.tuning.smbo``, ``pipeline.tuning.rung_board``): in id order, each when a
    worker is free and trials 0..t-lag have ended; at the end of rung r (frame ``ends[r]``, a
    count) a trial posts and waits until every earlier trial has posted there or ended; one
    that ran exactly to a rung stopped there, after its wait. Every trial's times depend on
    the earlier ones only, so one pass in id order schedules them."""
    free: list[float] = []  # end times of the trials on the workers
    ended: list[float] = []
    ready = [0.0] * len(ends)  # when every trial so far has posted at rung r or ended
    work = waiting = 0.0
    for t, (n, spf) in enumerate(zip(ran, seconds_per_frame, strict=True)):
        start = max(free[0] if len(free) == workers else 0.0,
                    max(ended[:max(t - lag + 1, 0)], default=0.0))
        if len(free) == workers:
            heapq.heappop(free)
        clock, done, posts = start, 0, []
        for r, end in enumerate(ends):
            if n < end:
                break
            clock += (end - done) * spf
            done = end
            posts.append(clock)
            waited = max(ready[r] - clock, 0.0)
            waiting += waited
            clock += waited
            if n == end and n < frames:
                break
        else:
            clock += (frames - done) * spf
            done = frames
        work += done * spf
        ended.append(clock)
        heapq.heappush(free, clock)
        ready = [max(ready[r], posts[r] if r < len(posts) else clock) for r in range(len(ends))]
    return Schedule(max(ended, default=0.0), work, waiting)


def promotion_row(p: Promotion, frames: int, workers: int) -> Row:
    from pipeline.tuning.smbo import told_lag

    rates = ", ".join(f"rung {r}: {100 * x:.0f} %" for r, x in enumerate(p.rates))
    used = (f"the model's; scheduled on {WORKERS} workers: waiting at the rungs "
            f"{100 * p.waiting:.1f} % of the work, makespan x{p.makespan or math.nan:.2f} the "
            f"work / {WORKERS}" if workers == WORKERS else "not the model's")
    return Row(f"successive halving, measured: NDT study of {p.trials} proposals on "
               f"{HALVING_SEQUENCE}'s first {frames} frames (proposals lag "
               f"{told_lag(workers)}: {workers} worker{'s' if workers > 1 else ''}), fraction "
               "of frames run", 100 * p.fraction, "%",
               f"trials going on after {rates} ({used}); the study took "
               f"{p.cpu_s / 60:.1f} CPU-min")


# -- the protocol model ------------------------------------------------------------------

CostKind = Literal["default", "sampled", "cached", "decode"]


def frame_costs(drive: Drive, costs: dict[str, Cost], kind: CostKind) -> np.ndarray:
    """CPU seconds of every frame of ``drive`` (its environment's cost): with the defaults,
    a sampled set, a sampled set over cached scans, or decoding the frame (``Cost``)."""
    def one(c: Cost) -> float:
        if kind == "cached" and not math.isnan(c.cpu_cached):
            return c.cpu_cached
        if kind == "decode":
            return c.cpu_decode
        return c.cpu_default if kind == "default" else c.cpu_sampled

    per = {env: one(c) for env, c in costs.items()}
    return np.array([per[env] for env in drive.environments])


def decoded_size(drive: Drive, costs: dict[str, Cost]) -> float:
    """Bytes of ``drive``'s scans decoded (its environments' bytes per frame)."""
    return float(sum(costs[env].bytes_per_frame for env in drive.environments))


def study_cost(drives: list[Drive], costs: list[np.ndarray], rates: list[float],
               halving: HalvingSection, length_m: float = LENGTH_M) -> tuple[float, float]:
    """(CPU seconds of one trial on average, of one whole trial) of a study over ``drives``
    under successive halving with promotion ``rates``: its rungs as the study makes them
    (``pipeline.tuning.pruning.rungs``: prefixes side by side, or whole sequences), each rung
    paying the frames it runs beyond the one before, at the share of trials that reach it.
    A rung is checked (and ``rates[r]`` applied) where a segment of ``length_m`` has ended on
    one of the sequences it ran."""
    from pipeline.tuning.pruning import rungs

    points = [p.frames for p in rungs([d.frames for d in drives], halving)]
    ends = tuple(d.frames - 1 for d in drives)
    done = [-1] * len(drives)
    mean, share = 0.0, 1.0
    for r, frames in enumerate([*points, ends]):
        mean += share * sum(float(c[p + 1:f + 1].sum())
                            for c, p, f in zip(costs, done, frames, strict=True) if f > p)
        done = [max(p, f) for p, f in zip(done, frames, strict=True)]
        checked = r < len(points) and any(
            f >= 0 and d.distance_m[f] > length_m for d, f in zip(drives, frames, strict=True))
        if checked and r < len(rates):
            share *= rates[r]
    return mean, float(sum(c.sum() for c in costs))


def makespan(jobs: list[float], workers: int) -> float:
    """Longest processing time first schedule of ``jobs`` [s] on ``workers``: its length."""
    load = [0.0] * workers
    for job in sorted(jobs, reverse=True):
        heapq.heapreplace(load, load[0] + job)
    return max(load)


@dataclass(frozen=True)
class Plan:
    """What a run of the protocol runs: the training sequences (every sequence of the drives is
    evaluated), the SMBO budgets, L [m], the rungs of the per-sequence and of the joint studies
    (None: the params' ``trials.halving``, the joint study's with ``joint_unit``), the workers
    and the memory they share [bytes]. The defaults are the paper's protocol on WORKERS workers
    of a MEMORY_BYTES workstation."""

    train: tuple[str, ...] = TRAIN
    iterations: int = ITERATIONS
    joint_iterations: int = ITERATIONS
    length_m: float = LENGTH_M
    halving: HalvingSection | None = None
    joint_halving: HalvingSection | None = None
    joint_unit: RungUnit = "prefix"
    workers: int = WORKERS
    memory_bytes: int = MEMORY_BYTES

    def cache_bytes(self) -> int:
        """The scan cache of one worker (``pipeline.tuning.worker.scan_cache_limit_bytes`` of
        its share of the memory)."""
        from pipeline.tuning.worker import scan_cache_limit_bytes

        return scan_cache_limit_bytes(self.memory_bytes // self.workers, self.memory_bytes)

    def rungs(self) -> tuple[HalvingSection, HalvingSection]:
        """(the per-sequence studies' rungs, the joint study's)."""
        per_sequence = self.halving or halving_settings(self.length_m).halving  # type: ignore[attr-defined]
        joint = self.joint_halving or per_sequence.model_copy(update={"unit": self.joint_unit})
        return per_sequence, joint


@dataclass
class Protocol:
    """CPU seconds of one way of running the protocol, by part, and its wall seconds on the
    plan's workers."""

    studies_s: float
    joint_s: float
    evaluate_s: float
    wall_s: float

    @property
    def core_s(self) -> float:
        return self.studies_s + self.joint_s + self.evaluate_s


def protocol_cost(drives: dict[str, Drive], costs: dict[str, Cost], promotion: Promotion,
                  halving: bool, plan: Plan = Plan()) -> Protocol:
    """The model of the module docstring for one adapter's ``costs`` over ``drives`` (every
    one evaluated, ``plan.train`` tuned), whole trials or ``halving``."""
    per_sequence, joint_rungs = plan.rungs()
    per_frame = {kind: {s: frame_costs(drives[s], costs, kind) for s in drives}
                 for kind in ("default", "sampled", "cached", "decode")}
    cache = plan.cache_bytes()

    def study(names: list[str], rungs: HalvingSection, budget: int) -> tuple[float, float]:
        """(CPU seconds, wall seconds) of a study of ``budget`` trials over ``names``: its
        trials over cached scans, every worker decoding them once, where they fit the cache."""
        fits = sum(decoded_size(drives[s], costs) for s in names) <= cache
        trial_costs = per_frame["cached" if fits else "sampled"]
        mean, whole = study_cost([drives[s] for s in names], [trial_costs[s] for s in names],
                                 promotion.rates, rungs, plan.length_m)
        decode = (sum(float(per_frame["decode"][s].sum()) for s in names) if fits else 0.0)
        trial = mean if halving else whole
        if not halving:
            wall = decode + math.ceil(budget / plan.workers) * whole
        elif promotion.makespan is None:
            wall = decode + budget * trial / plan.workers + whole
        else:
            wall = decode + promotion.makespan * budget * trial / plan.workers
        return budget * trial + min(plan.workers, budget) * decode, wall

    parts = [study([s], per_sequence, plan.iterations) for s in plan.train]
    joint = study(list(plan.train), joint_rungs, plan.joint_iterations)
    adaptive = [float(per_frame["sampled"][s].sum()) for s in drives]
    evaluate = [float(per_frame["default"][s].sum() + per_frame["sampled"][s].sum())
                for s in drives]
    wall = (sum(w for _, w in parts) + joint[1] + makespan(adaptive, plan.workers)
            + makespan(evaluate, plan.workers))
    return Protocol(sum(c for c, _ in parts), joint[0], sum(adaptive) + sum(evaluate), wall)


def protocol_rows(name: str, costs: dict[str, Cost], drives: dict[str, Drive],
                  promotion: Promotion) -> list[Row]:
    """The bench line of ``name`` and its preset's own budgets."""
    whole = protocol_cost(drives, costs, promotion, False)
    halving = protocol_cost(drives, costs, promotion, True)
    preset = [protocol_cost(drives, costs, promotion, h, Plan(joint_iterations=PRESET_JOINT))
              for h in (False, True)]
    frames = sum(d.frames for d in drives.values())
    return [
        Row(f"full protocol core-hours {name}: whole {whole.core_s / 3600:.0f}, "
            f"multi-fidelity {halving.core_s / 3600:.0f}", halving.core_s / 3600, "core-h",
            f"{frames} frames, {ITERATIONS} + {ITERATIONS} SMBO proposals; wall on "
            f"{WORKERS} workers: whole {whole.wall_s / 3600:.1f} h, multi-fidelity "
            f"{halving.wall_s / 3600:.1f} h", "GICP <= 50, KISS-ICP <= 40, NDT <= 10; wall "
            "<= 6 h"),
        Row(f"  the preset's budgets ({ITERATIONS} per sequence, {PRESET_JOINT} joint "
            f"warm-started), core-hours {name}: whole {preset[0].core_s / 3600:.0f}, "
            f"multi-fidelity {preset[1].core_s / 3600:.0f}", preset[1].core_s / 3600,
            "core-h", f"wall on {WORKERS} workers: whole {preset[0].wall_s / 3600:.1f} h, "
            f"multi-fidelity {preset[1].wall_s / 3600:.1f} h", "-"),
    ]
