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
from pipeline.realism.compare import TARGET_RATIO, RealismResult
from pipeline.realism.statistics import RANGE_EDGES_M, ScanStatistics


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
    """The JSON document: settings, per slice statistics and step errors, pooled 90th
    percentiles, the ratios simulated / real and whether each is within the target."""
    pooled = {a: {side: {what: result.pooled_p90(a, side, what) for what in ("t_cm", "r_deg")}
                  for side in ("real", "sim")} for a in result.algorithms}
    return {"replicas": result.replicas, "sensor": result.sensor, "beams": result.beams,
            "settings": result.settings,
            "target_ratio": TARGET_RATIO,
            "slices": [asdict(s) for s in result.slices], "pooled_p90": pooled,
            "ratios": result.ratios(), "within_target": result.within_target()}


def _ratio(sim: float, real: float) -> str:
    r = sim / real
    mark = "" if 1.0 / TARGET_RATIO <= r <= TARGET_RATIO else " !"
    return f"{r:.2f}{mark}"


def markdown(result: RealismResult) -> str:
    """The frame-to-frame error table (per slice and algorithm: median t [cm] and r [deg], real
    and simulated, simulated replicas' range, ratio; then the pooled 90th percentiles) and the
    scan statistics table. ``!`` marks a ratio outside [1/1.5, 1.5]."""
    lines = [f"Frame-to-frame error, defaults; simulated: {result.replicas} replicas "
             "(median over their steps, [min-max of the replicas' medians]).", "",
             "| slice | env | algorithm | real t [cm] | sim t [cm] | sim/real | real r [deg] "
             "| sim r [deg] | sim/real |", "|---|---|---|---|---|---|---|---|---|"]
    for s in result.slices:
        for a in result.algorithms:
            re, si = s.real[a], s.sim[a]
            lines.append(
                f"| {s.sequence} {s.first}-{s.last} | {s.environment} | {a} "
                f"| {re.median_t_cm:.2f} | {si.median_t_cm:.2f} [{min(si.replica_t_cm):.2f}-"
                f"{max(si.replica_t_cm):.2f}] | {_ratio(si.median_t_cm, re.median_t_cm)} "
                f"| {re.median_r_deg:.3f} | {si.median_r_deg:.3f} [{min(si.replica_r_deg):.3f}-"
                f"{max(si.replica_r_deg):.3f}] | {_ratio(si.median_r_deg, re.median_r_deg)} |")
    for a in result.algorithms:
        rt, st = result.pooled_p90(a, "real", "t_cm"), result.pooled_p90(a, "sim", "t_cm")
        rr, sr = result.pooled_p90(a, "real", "r_deg"), result.pooled_p90(a, "sim", "r_deg")
        lines.append(f"| all, p90 | | {a} | {rt:.2f} | {st:.2f} | {_ratio(st, rt)} | {rr:.3f} "
                     f"| {sr:.3f} | {_ratio(sr, rr)} |")
    within = result.within_target()
    return "\n".join([*lines, "", *_scan_table(result), "",
                      f"Within x{TARGET_RATIO:g}: {sum(within.values())} of {len(within)} "
                      "figures."]) + "\n"


RING_GROUPS = 4
"""The returns per ring are shown as the mean over this many equal groups of rings."""


def _scan_table(result: RealismResult) -> list[str]:
    """The scan statistics table's lines (``markdown``)."""
    bins = [f"{a:g}-{b:g}" for a, b in itertools.pairwise(RANGE_EDGES_M)]
    lines = ["Scan statistics (real / simulated): points a scan, lost returns, share of points "
             f"by range [m] ({', '.join(bins)}), rings recovered from the points' order (the "
             f"fewest in a scan; ! fewer than the sensor's {result.beams}: the returns a ring "
             f"are then off), returns a ring and scan, mean over {RING_GROUPS} groups of rings "
             "(top first).", "",
             "| slice | points | lost | range shares [%] | rings | returns a ring |",
             "|---|---|---|---|---|---|"]
    for s in result.slices:
        re, si = s.real_stats, s.sim_stats
        shares = " ".join(f"{100 * r:.0f}/{100 * m:.0f}" for r, m in
                          zip(re.range_share, si.range_share, strict=True))
        rings = " / ".join(f"{x.rings_found}{'' if x.rings_found == result.beams else ' !'}"
                           for x in (re, si))
        groups = " ".join(f"{r:.0f}/{m:.0f}" for r, m in
                          zip(_ring_groups(re), _ring_groups(si), strict=True))
        lines.append(f"| {s.sequence} | {re.points:.0f} / {si.points:.0f} "
                     f"| {100 * re.lost_share:.1f} / {100 * si.lost_share:.1f} % | {shares} "
                     f"| {rings} | {groups} |")
    return lines


def _ring_groups(stats: ScanStatistics) -> list[float]:
    """Mean returns a ring and scan over each of ``RING_GROUPS`` equal groups of rings."""
    return [float(np.mean(g)) for g in np.array_split(np.array(stats.ring_returns),
                                                       RING_GROUPS)]


def figure(result: RealismResult, out_png: Path) -> None:
    """Top row: per slice the median step errors (t, r) of each algorithm, real against
    simulated (bars: the replicas' range). Bottom row: range histogram, returns per ring and
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
            sim = [np.median(getattr(s.sim[a], what)) for s in result.slices]
            reps = [getattr(s.sim[a], "replica_" + what) for s in result.slices]
            lo = [m - min(r) for m, r in zip(sim, reps, strict=True)]
            hi = [max(r) - m for m, r in zip(sim, reps, strict=True)]
            ax.plot(x - 0.1, real, "ko", label="real")
            ax.errorbar(x + 0.1, sim, yerr=[lo, hi], fmt="s", color="tab:red", capsize=3,
                        label="simulated")
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
