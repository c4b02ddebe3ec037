"""The comparison's outputs: ``realism.json`` (everything), ``realism.md`` (the tables) and
``realism.png`` (real and simulated side by side); docs/design.md, "The sim-to-real
comparison"."""

from __future__ import annotations

import itertools
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.io_utils import atomic_write_text, output_folder
from studies.realism.compare import TARGET_RATIO, RealismResult
from studies.realism.statistics import RANGE_EDGES_M, ScanStatistics


def write_realism(result: RealismResult, out_dir: str | Path) -> list[Path]:
    """Write the three outputs into ``out_dir`` (created when missing; each file atomically);
    their paths."""
    from pipeline.report.outputs import write_json

    out = output_folder(out_dir)
    paths = [out / "realism.json", out / "realism.md", out / "realism.png"]
    write_json(paths[0], summary(result))
    atomic_write_text(paths[1], markdown(result))
    figure(result, paths[2])
    return paths


def summary(result: RealismResult) -> dict[str, Any]:
    """The JSON document: settings, per slice statistics, step errors and ground-truth error,
    pooled 90th percentiles, the ratios simulated / real (with the ground-truth error added:
    ``ratios``; against the exact ground truth: ``ratios_exact_gt``) and whether each is
    within the target."""
    pooled = {a: {side: {what: result.pooled_p90(a, side, what) for what in ("t_cm", "r_deg")}
                  for side in ("real", "sim", "sim_gt")} for a in result.algorithms}
    return {"replicas": result.replicas, "sensor": result.sensor, "beams": result.beams,
            "settings": result.settings,
            "target_ratio": TARGET_RATIO,
            "slices": [asdict(s) for s in result.slices], "pooled_p90": pooled,
            "ratios": result.ratios(), "ratios_exact_gt": result.ratios("sim"),
            "within_target": result.within_target(),
            "ratio_ranges": result.ratio_ranges(),
            "beyond_real_noise": result.beyond_real_noise()}


def _ratio(sim: float, real: float) -> str:
    r = sim / real
    mark = "" if 1.0 / TARGET_RATIO <= r <= TARGET_RATIO else " !"
    return f"{r:.2f}{mark}"


def markdown(result: RealismResult) -> str:
    """The frame-to-frame error table (per slice and algorithm: median t [cm] and r [deg],
    real, simulated against the exact ground truth, simulated with the ground-truth error
    added and its replicas' range, ratio of the latter to real; then the pooled 90th
    percentiles), the ground-truth error table and the scan statistics table. ``!`` marks a
    ratio outside [1/1.5, 1.5]."""
    lines = [f"Frame-to-frame error at the defaults. sim: against the exact ground truth; "
             f"sim+gt: with the slice's ground-truth error added; {result.replicas} replicas "
             "(median over their steps, [min-max of the replicas' medians]).", "",
             "| slice | env | algorithm | real t [cm] | sim t | sim+gt t | ratio "
             "| real r [deg] | sim r | sim+gt r | ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in result.slices:
        for a in result.algorithms:
            re, ex, si = s.real[a], s.sim[a], s.sim_gt[a]
            lines.append(
                f"| {s.sequence} {s.first}-{s.last} | {s.environment} | {a} "
                f"| {re.median_t_cm:.2f} | {ex.median_t_cm:.2f} | {si.median_t_cm:.2f} "
                f"[{min(si.replica_t_cm):.2f}-{max(si.replica_t_cm):.2f}] "
                f"| {_ratio(si.median_t_cm, re.median_t_cm)} "
                f"| {re.median_r_deg:.3f} | {ex.median_r_deg:.3f} | {si.median_r_deg:.3f} "
                f"[{min(si.replica_r_deg):.3f}-{max(si.replica_r_deg):.3f}] "
                f"| {_ratio(si.median_r_deg, re.median_r_deg)} |")
    for a in result.algorithms:
        p90 = {(side, w): result.pooled_p90(a, side, w) for side in ("real", "sim", "sim_gt")
               for w in ("t_cm", "r_deg")}
        lines.append(
            f"| all, p90 | | {a} | {p90['real', 't_cm']:.2f} | {p90['sim', 't_cm']:.2f} "
            f"| {p90['sim_gt', 't_cm']:.2f} | {_ratio(p90['sim_gt', 't_cm'], p90['real', 't_cm'])}"
            f" | {p90['real', 'r_deg']:.3f} | {p90['sim', 'r_deg']:.3f} "
            f"| {p90['sim_gt', 'r_deg']:.3f} "
            f"| {_ratio(p90['sim_gt', 'r_deg'], p90['real', 'r_deg'])} |")
    within, exact = result.within_target(), result.within_target("sim")
    return "\n".join([*lines, "", *_real_noise_table(result), "", *_ground_truth_table(result),
                      "", *_scan_table(result), "",
                      f"Within x{TARGET_RATIO:g}: {sum(within.values())} of {len(within)} "
                      f"figures with the ground-truth error added ({sum(exact.values())} "
                      "against the exact ground truth)."]) + "\n"


def _real_noise_table(result: RealismResult) -> list[str]:
    """Per slice and algorithm: the real median's interval (order statistics of its steps) and
    the ratio's range against it; ``!!`` where the whole range is outside x1.5."""
    intervals, ranges = result.real_intervals(), result.ratio_ranges()
    beyond = result.beyond_real_noise()
    coverage = {c for _, _, c in intervals.values()}
    lines = ["The real side's own noise: a slice's real median comes from its few steps; its "
             "distribution-free interval (order statistics, coverage "
             f"{', '.join(f'{c:.1%}' for c in sorted(coverage))}) and the ratio sim+gt / real "
             "against the interval's ends. `!!`: the whole range is outside "
             f"x{TARGET_RATIO:g}, a miss the real side's noise does not explain.", "",
             "| slice | algorithm | real t interval [cm] | ratio range t "
             "| real r interval [deg] | ratio range r |", "|---|---|---|---|---|---|"]
    for s in result.slices:
        for a in result.algorithms:
            cells = []
            for key, digits in (("t", 2), ("r", 3)):
                name = f"{a} {s.sequence} median {key}"
                low, high, _ = intervals[name]
                r_low, r_high = ranges[name]
                mark = " !!" if beyond[name] else ""
                cells.append(f"{low:.{digits}f}-{high:.{digits}f} "
                             f"| {r_low:.2f}-{r_high:.2f}{mark}")
            lines.append(f"| {s.sequence} {s.first}-{s.last} | {a} | {cells[0]} | {cells[1]} |")
    lines += ["", f"Beyond the real side's noise: {sum(beyond.values())} of {len(beyond)} "
              "per-slice medians."]
    return lines


def _ground_truth_table(result: RealismResult) -> list[str]:
    """The ground-truth error table's lines (``markdown``)."""
    lines = ["Ground-truth error of a step: its bias, the step error both odometries share on "
             "the real slice, and the median of its white noise (from the trajectory).", "",
             "| slice | bias t [cm] | bias r [deg] | white t [cm] | white r [deg] |",
             "|---|---|---|---|---|"]
    for s in result.slices:
        g = s.gt_error
        bias_t = "-" if g is None else f"{100 * float(np.linalg.norm(g.mean[:3])):.2f}"
        bias_r = "-" if g is None else f"{np.rad2deg(float(np.linalg.norm(g.mean[3:]))):.3f}"
        lines.append(f"| {s.sequence} | {bias_t} | {bias_r} | {s.gt_white[0]:.2f} "
                     f"| {s.gt_white[1]:.3f} |")
    return lines


RING_GROUPS = 4
"""The returns per ring are shown as the mean over this many equal groups of rings."""


def _scan_table(result: RealismResult) -> list[str]:
    """The scan statistics table's lines (``markdown``)."""
    bins = [f"{a:g}-{b:g}" for a, b in itertools.pairwise(RANGE_EDGES_M)]
    lines = ["Scan statistics (real / simulated): points a scan, lost returns, thickness of the "
             f"road 4-10 m away, share of points by range [m] ({', '.join(bins)}), rings "
             "recovered from the points' order (the fewest in a scan; ! fewer than the "
             f"sensor's {result.beams}: the returns a ring are then off), returns a ring and "
             f"scan, mean over {RING_GROUPS} groups of rings (top first).", "",
             "| slice | points | lost | road thickness [mm] | range shares [%] | rings "
             "| returns a ring |",
             "|---|---|---|---|---|---|---|"]
    for s in result.slices:
        re, si = s.real_stats, s.sim_stats
        shares = " ".join(f"{100 * r:.0f}/{100 * m:.0f}" for r, m in
                          zip(re.range_share, si.range_share, strict=True))
        rings = " / ".join(f"{x.rings_found}{'' if x.rings_found == result.beams else ' !'}"
                           for x in (re, si))
        groups = " ".join(f"{r:.0f}/{m:.0f}" for r, m in
                          zip(_ring_groups(re), _ring_groups(si), strict=True))
        lines.append(f"| {s.sequence} | {re.points:.0f} / {si.points:.0f} "
                     f"| {100 * re.lost_share:.1f} / {100 * si.lost_share:.1f} % "
                     f"| {re.road_planarity_mm:.1f} / {si.road_planarity_mm:.1f} | {shares} "
                     f"| {rings} | {groups} |")
    return lines


def _ring_groups(stats: ScanStatistics) -> list[float]:
    """Mean returns a ring and scan over each of ``RING_GROUPS`` equal groups of rings."""
    return [float(np.mean(g)) for g in np.array_split(np.array(stats.ring_returns),
                                                       RING_GROUPS)]


def figure(result: RealismResult, out_png: Path) -> None:
    """Top row: per slice the median step errors (t, r) of each algorithm, real against
    simulated with the ground-truth error added (bars: the replicas' range) and against the
    exact ground truth (open squares). Bottom row: range histogram, returns per ring and
    points a scan, real against simulated (all slices)."""
    from pipeline.report.outputs import figure as report_figure

    algos = result.algorithms
    with report_figure(out_png, 2, 2 * len(algos), (4.2 * 2 * len(algos), 8)) as (_, axes):
        _draw(result, axes)


def _draw(result: RealismResult, axes: Any) -> None:
    """The panels of ``figure`` on its (2, 2 * algorithms) ``axes``."""
    import matplotlib.pyplot as plt

    algos = result.algorithms
    names = [s.sequence for s in result.slices]
    x = np.arange(len(names))
    for i, a in enumerate(algos):
        for j, (what, unit) in enumerate((("t_cm", "t [cm]"), ("r_deg", "r [deg]"))):
            ax = axes[0, 2 * i + j]
            real = [np.median(getattr(s.real[a], what)) for s in result.slices]
            exact = [np.median(getattr(s.sim[a], what)) for s in result.slices]
            sim = [np.median(getattr(s.sim_gt[a], what)) for s in result.slices]
            reps = [getattr(s.sim_gt[a], "replica_" + what) for s in result.slices]
            lo = [m - min(r) for m, r in zip(sim, reps, strict=True)]
            hi = [max(r) - m for m, r in zip(sim, reps, strict=True)]
            ax.plot(x - 0.15, real, "ko", label="real")
            ax.errorbar(x + 0.15, sim, yerr=[lo, hi], fmt="s", color="tab:red", capsize=3,
                        label="simulated + gt error")
            ax.plot(x + 0.15, exact, "s", mfc="none", color="tab:red",
                    label="simulated, exact gt")
            ax.set_xticks(x, names)
            ax.set_ylim(bottom=0)
            ax.set_title(f"{a}: median step error {unit}")
            ax.legend(fontsize=8)
    centres = 0.5 * (np.array(RANGE_EDGES_M[:-1]) + np.minimum(RANGE_EDGES_M[1:], 100.0))
    for s, colour in zip(result.slices, plt.rcParams["axes.prop_cycle"].by_key()["color"],
                         strict=False):
        axes[1, 0].plot(centres, s.real_stats.range_share, "-", color=colour,
                        label=f"{s.sequence} real")
        axes[1, 0].plot(centres, s.sim_stats.range_share, "--", color=colour,
                        label=f"{s.sequence} sim")
        axes[1, 1].plot(s.real_stats.ring_returns, "-", color=colour)
        axes[1, 1].plot(s.sim_stats.ring_returns, "--", color=colour)
    axes[1, 0].set_title("share of points by range (- real, -- sim)")
    axes[1, 0].set_xlabel("range [m]")
    axes[1, 0].legend(fontsize=7, ncol=2)
    axes[1, 1].set_title("returns per ring and scan (- real, -- sim)")
    axes[1, 1].set_xlabel("ring (0 = highest)")
    if axes.shape[1] > 2:
        ax = axes[1, 2]
        ax.bar(x - 0.2, [s.real_stats.points for s in result.slices], 0.4, color="k",
               label="real")
        ax.bar(x + 0.2, [s.sim_stats.points for s in result.slices], 0.4, color="tab:red",
               label="simulated")
        ax.set_xticks(x, names)
        ax.set_title("points a scan")
        ax.legend(fontsize=8)
        ax = axes[1, 3] if axes.shape[1] > 3 else None
        if ax is not None:
            ax.bar(x - 0.2, [100 * s.real_stats.lost_share for s in result.slices], 0.4,
                   color="k", label="real")
            ax.bar(x + 0.2, [100 * s.sim_stats.lost_share for s in result.slices], 0.4,
                   color="tab:red", label="simulated")
            ax.set_xticks(x, names)
            ax.set_title("lost returns [%]")
