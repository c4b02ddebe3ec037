"""The sim-to-real comparison (docs/design.md, "The sim-to-real comparison").

For every slice (a KITTI sequence's frames ``first`` .. ``last``): the real scans, and
``replicas`` simulations of the same frames (simulated KITTI, world seed ``replica_seed(r, NN)``
for replica r, the ``simulate_kitti`` section's sensor). Each side gets its scan statistics and
the frame-to-frame errors of every algorithm at its defaults: per slice the median over the
slice's steps (simulated: over all replicas' steps, and each replica's own median for the
spread), and the 90th percentile over every slice's steps pooled. The real errors include the
ground truth's own error; the simulated ones are given both against the exact ground truth
(``sim``) and with the slice's ground-truth error added (``sim_gt``,
``studies.realism.ground_truth``), which is what the target compares.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.io_utils import check_plain_name
from pipeline.progress import PROGRESS, progress
from pipeline.sim.kitti_dataset import SimulateKittiSection
from studies.realism.ground_truth import GroundTruthError
from studies.realism.statistics import ScanStatistics, scan_statistics

SLICES = (("01", 0, 9), ("04", 0, 9), ("06", 0, 9), ("10", 0, 9))
"""(sequence, first, last frame) of the real slices (../shared/data/kitti_mini)."""
ALGORITHMS = ("gicp", "kiss_icp")
TARGET_RATIO = 1.5
"""Calibration target: simulated / real within [1 / TARGET_RATIO, TARGET_RATIO]."""
MEDIAN_CONFIDENCE = 0.95
"""The least coverage of a real median's interval (``median_interval``)."""


@dataclass
class SideErrors:
    """Step errors of one algorithm on one side of one slice: translational [cm] and rotational
    [deg] errors of every step (all replicas' steps on the simulated side), and each replica's
    median translational / rotational error (one entry on the real side)."""

    t_cm: list[float]
    r_deg: list[float]
    replica_t_cm: list[float] = field(default_factory=list)
    replica_r_deg: list[float] = field(default_factory=list)

    @property
    def median_t_cm(self) -> float:
        return float(np.median(self.t_cm))

    @property
    def median_r_deg(self) -> float:
        return float(np.median(self.r_deg))


@dataclass
class SliceResult:
    """One slice: statistics and errors (algorithm -> side) of the real and simulated scans;
    ``sim_gt`` the simulated errors with the slice's ground-truth error added (``gt_error``,
    None when fewer than two algorithms ran: then ``sim_gt`` is ``sim``); ``gt_white`` the
    white-noise bound of the ground truth around the slice (t [cm], r [deg])."""

    sequence: str
    first: int
    last: int
    environment: str
    real_stats: ScanStatistics
    sim_stats: ScanStatistics
    real: dict[str, SideErrors]
    sim: dict[str, SideErrors]
    sim_gt: dict[str, SideErrors]
    gt_error: GroundTruthError | None
    gt_white: tuple[float, float]


@dataclass
class RealismResult:
    """Every slice, and the settings that made it (``beams``: the sensor's rings)."""

    slices: list[SliceResult]
    algorithms: tuple[str, ...]
    replicas: int
    sensor: str
    beams: int
    settings: dict[str, object]

    def pooled_p90(self, algorithm: str, side: str, what: str) -> float:
        """90th percentile of ``what`` ("t_cm" | "r_deg") over every slice's steps; side
        "real", "sim" or "sim_gt"."""
        vals = [v for s in self.slices for v in getattr(getattr(s, side)[algorithm], what)]
        return float(np.percentile(vals, 90))

    def ratios(self, side: str = "sim_gt") -> dict[str, float]:
        """Simulated (``side``) / real of every calibrated figure: ``<algo> <slice> median t``,
        ..., ``<algo> pooled p90 t``, ...; the target is every ratio in [1 / 1.5, 1.5]."""
        out: dict[str, float] = {}
        for a in self.algorithms:
            for s in self.slices:
                sim = getattr(s, side)[a]
                out[f"{a} {s.sequence} median t"] = sim.median_t_cm / s.real[a].median_t_cm
                out[f"{a} {s.sequence} median r"] = sim.median_r_deg / s.real[a].median_r_deg
            for what, key in (("t_cm", "t"), ("r_deg", "r")):
                out[f"{a} pooled p90 {key}"] = (self.pooled_p90(a, side, what)
                                                / self.pooled_p90(a, "real", what))
        return out

    def within_target(self, side: str = "sim_gt") -> dict[str, bool]:
        return {k: 1.0 / TARGET_RATIO <= v <= TARGET_RATIO
                for k, v in self.ratios(side).items()}

    def real_intervals(self) -> dict[str, tuple[float, float, float]]:
        """Per slice median (``ratios``' keys ``<algo> <slice> median t`` and ``r``): the real
        median's interval (low, high, coverage) from its steps (``median_interval``)."""
        return {f"{a} {s.sequence} median {key}": median_interval(steps)
                for a in self.algorithms for s in self.slices
                for key, steps in (("t", s.real[a].t_cm), ("r", s.real[a].r_deg))}

    def ratio_ranges(self, side: str = "sim_gt") -> dict[str, tuple[float, float]]:
        """Per slice, the ratio of every median against the ends of the real median's interval
        (``real_intervals``): the simulated median over the real interval's high end, then over
        its low end. Nine steps give the real median a wide interval; the simulated one pools
        every replica's steps."""
        intervals = self.real_intervals()
        out: dict[str, tuple[float, float]] = {}
        for a in self.algorithms:
            for s in self.slices:
                sim = getattr(s, side)[a]
                for key, median in (("t", sim.median_t_cm), ("r", sim.median_r_deg)):
                    name = f"{a} {s.sequence} median {key}"
                    low, high, _ = intervals[name]
                    out[name] = (median / high, median / low)
        return out

    def beyond_real_noise(self, side: str = "sim_gt") -> dict[str, bool]:
        """Per slice median: True when its whole ``ratio_ranges`` lies outside the target's
        [1 / 1.5, 1.5], so the miss is not the real slice's few steps."""
        return {k: high < 1.0 / TARGET_RATIO or low > TARGET_RATIO
                for k, (low, high) in self.ratio_ranges(side).items()}


def median_interval(values: Sequence[float], confidence: float = MEDIAN_CONFIDENCE
                    ) -> tuple[float, float, float]:
    """(low, high, coverage): the distribution-free interval of the median of ``values`` from
    their order statistics, [x(j), x(n + 1 - j)] with the largest j whose coverage
    P(j <= B <= n - j), B ~ Binomial(n, 1/2), is at least ``confidence`` (j = 1 when even the
    extremes fall short: then the coverage says so). n = 9: x(2) .. x(8), 96.1 %."""
    from scipy.stats import binom

    x = np.sort(np.asarray(values, dtype=np.float64))
    n = len(x)
    if n == 0:
        raise ValueError("median_interval needs at least one value")
    j = 1
    while j + 1 <= n - j and 1.0 - 2.0 * binom.cdf(j, n, 0.5) >= confidence:
        j += 1
    return float(x[j - 1]), float(x[n - j]), float(1.0 - 2.0 * binom.cdf(j - 1, n, 0.5))


def parse_slice(text: str) -> tuple[str, int, int]:
    """``"04:0:9"`` -> ("04", 0, 9); ConfigError naming the text and the rule otherwise (NN a
    plain name: it becomes the file names NN.txt, sequences/NN)."""
    parts = text.split(":")
    try:
        seq, first, last = parts[0], int(parts[1]), int(parts[2])
    except (IndexError, ValueError):
        raise ConfigError(f"a slice is NN:FIRST:LAST, e.g. 04:0:9, got {text!r}") from None
    if len(parts) != 3 or not 0 <= first < last:
        raise ConfigError(f"a slice is NN:FIRST:LAST with 0 <= FIRST < LAST, got {text!r}")
    return check_plain_name(seq, f"the sequence of slice {text!r}"), first, last


def run_realism(kitti_root: str | Path, trajectories: str | Path,
                section: SimulateKittiSection, replicas: int = 3,
                slices: tuple[tuple[str, int, int], ...] = SLICES,
                algorithms: tuple[str, ...] = ALGORITHMS) -> RealismResult:
    """Compare the real ``slices`` under ``kitti_root`` with ``replicas`` simulations of each
    (module docstring); the simulated side follows ``trajectories``/NN.txt and ``section``."""
    from pipeline.sim.kitti_dataset import kitti_sensor
    from pipeline.sim.kitti_world import frame_environments

    if replicas < 1:
        raise ConfigError(f"replicas must be >= 1, got {replicas}")
    if not slices:
        raise ConfigError("realism needs at least one slice")
    for seq, _, last in slices:  # an unknown sequence fails here, before any odometry runs
        frame_environments(check_plain_name(seq, "a slice's sequence"), last + 1)
    sensor = kitti_sensor(section)
    done = [_compare_slice(Path(kitti_root), Path(trajectories), section, seq, a, b, replicas,
                           algorithms, sensor.beams, sensor.beams * sensor.azimuths)
            for seq, a, b in progress(slices, len(slices), "realism", unit="slice")]
    return RealismResult(done, tuple(algorithms), replicas, section.sensor, sensor.beams,
                         section.model_dump(mode="json"))


def _compare_slice(kitti_root: Path, trajectories: Path, section: SimulateKittiSection,
                   sequence: str, first: int, last: int, replicas: int,
                   algorithms: tuple[str, ...], beams: int, firings: int) -> SliceResult:
    """Real and simulated statistics and step errors of one slice."""
    from pipeline.sim.kitti import kitti_lidar_poses
    from pipeline.sim.kitti_world import frame_environments
    from studies.realism.ground_truth import shared_error, twists, white_noise, white_sigma
    from studies.realism.registration import odometry_step_errors
    from studies.realism.slices import real_slice, replica_seed, simulated_slice

    real = real_slice(kitti_root, sequence, first, last)
    what = f"{sequence} {first}-{last}"
    real_E = {a: odometry_step_errors(a, real, f"real {what}") for a in algorithms}
    around = kitti_lidar_poses(trajectories / f"{sequence}.txt")[0][max(0, first - 50):last + 51]
    gt = (shared_error(twists(real_E[algorithms[0]]), twists(real_E[algorithms[1]]),
                       white_sigma(around)) if len(algorithms) >= 2 else None)
    white = white_noise(around)
    sim_points: list[NDArray[np.float32]] = []
    runs: dict[str, list[NDArray[np.float64]]] = {a: [] for a in algorithms}
    with_gt: dict[str, list[NDArray[np.float64]]] = {a: [] for a in algorithms}
    for r in range(replicas):
        scans = simulated_slice(trajectories, sequence, first, last, section,
                                replica_seed(r, sequence))
        sim_points += [s.points_lidar for s in scans]
        for k, a in enumerate(algorithms):
            E = odometry_step_errors(a, scans, f"simulated {what}, replica {r}")
            runs[a].append(E)
            rng = np.random.default_rng([r, 97, zlib.crc32(sequence.encode()), k])
            with_gt[a].append(E if gt is None else gt.compose(E, rng))
    env = frame_environments(sequence, last + 1)[first]
    result = SliceResult(sequence, first, last, env,
                         scan_statistics([s.points_lidar for s in real], beams, firings),
                         scan_statistics(sim_points, beams, firings),
                         {a: _side([real_E[a]]) for a in algorithms},
                         {a: _side(runs[a]) for a in algorithms},
                         {a: _side(with_gt[a]) for a in algorithms}, gt, white)
    PROGRESS.info("realism %s (%s): %s", sequence, env, ", ".join(
        f"{a} t {result.real[a].median_t_cm:.2f} / {result.sim_gt[a].median_t_cm:.2f} cm"
        for a in algorithms))
    return result


def _side(runs: list[NDArray[np.float64]]) -> SideErrors:
    """The errors of the runs' step errors E (one (N, 4, 4) array a run)."""
    from studies.realism.registration import error_sizes

    sizes = [error_sizes(E) for E in runs]
    return SideErrors([float(v) for t, _ in sizes for v in t],
                      [float(v) for _, r in sizes for v in r],
                      [float(np.median(t)) for t, _ in sizes],
                      [float(np.median(r)) for _, r in sizes])
