"""The report's figures (matplotlib, Agg backend, PNG written atomically).

- ``schedule_figure``: the adaptively chosen parameters over time with the environment shaded
  (the paper's Fig. 5);
- ``trials_figure``: the parameters sampled by the SMBO of every training sequence, coloured by
  the trial's mean RTE (the paper's Fig. 4 and 6);
- ``rte_figure``: per-start-frame RTE of the three settings over the sequence;
- ``trajectory_figure``: top-down estimated and true trajectories.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.evaluate.result import SETTINGS, Evaluation
from pipeline.outputs import SETTING_COLOURS, figure
from pipeline.sequence import EnvLabel
from pipeline.sim.plot import LABEL_COLOURS


def _shade(ax: Any, labels: Sequence[EnvLabel], frame_s: float) -> None:
    """Shade the frame ranges of every environment label (time axis in seconds)."""
    seen = set()
    for lab in labels:
        colour = LABEL_COLOURS.get(lab.label, "tab:purple")
        ax.axvspan(lab.start * frame_s, (lab.end + 1) * frame_s, color=colour, alpha=0.12,
                   label=None if lab.label in seen else lab.label)
        seen.add(lab.label)


def _frame_s(stamps_ns: np.ndarray) -> float:
    return float(np.median(np.diff(stamps_ns))) * 1e-9 if len(stamps_ns) > 1 else 0.1


def schedule_figure(ev: Evaluation, sequence: str, out_png: Path) -> Path:
    """The adaptive parameters of ``sequence`` over time, one panel per parameter (Fig. 5)."""
    sched = ev.schedules[sequence]
    names = list(sched.values)
    frame_s = _frame_s(ev.score("adaptive", sequence).trajectory.stamps_ns)
    t = np.arange(len(sched)) * frame_s
    with figure(out_png, len(names), 1, (9, 1.9 * len(names) + 0.6), sharex=True) as (fig, axes):
        for ax, name in zip(axes[:, 0], names, strict=True):
            _shade(ax, ev.infos[sequence].labels, frame_s)
            ax.step(t, sched.values[name], where="post", color="tab:red", label="adaptive")
            ax.axhline(ev.fixed_params[name], color=SETTING_COLOURS["fixed"], ls="--",
                       label="fixed")
            ax.axhline(ev.baseline_params[name], color=SETTING_COLOURS["baseline"], ls=":",
                       label="baseline")
            ax.set_ylabel(name)
        axes[0, 0].legend(loc="upper right", fontsize=7, ncol=6)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"{ev.algorithm}: parameters chosen online on {sequence}")
    return out_png


def rte_figure(ev: Evaluation, sequence: str, out_png: Path) -> Path:
    """Per-start-frame RTE [%] of every setting over ``sequence``."""
    frame_s = _frame_s(ev.score("adaptive", sequence).trajectory.stamps_ns)
    with figure(out_png) as (_, axes):
        ax = axes[0, 0]
        _shade(ax, ev.infos[sequence].labels, frame_s)
        for setting in SETTINGS:
            s = ev.score(setting, sequence)
            ax.plot(np.arange(len(s.t_err_pct)) * frame_s, s.t_err_pct,
                    color=SETTING_COLOURS[setting], lw=1.2, label=f"{setting} ({s.rte_pct:.3g} %)")
        ax.set_yscale("log")
        ax.set_xlabel("segment start [s]")
        ax.set_ylabel(f"RTE over {ev.length_m:g} m [%]")
        ax.legend(fontsize=8)
        ax.set_title(f"{ev.algorithm} on {sequence}")
    return out_png


def trajectory_figure(ev: Evaluation, sequence: str, out_png: Path) -> Path:
    """Top-down trajectories: ground truth and every setting, started at the true first pose."""
    gt = ev.ground_truth[sequence]
    with figure(out_png, size=(7, 7)) as (_, axes):
        ax = axes[0, 0]
        ax.plot(gt[:, 0, 3], gt[:, 1, 3], color="black", lw=2, label="ground truth")
        for setting in SETTINGS:
            xy = aligned_positions(gt, ev.score(setting, sequence).trajectory.T_world_lidar)
            ax.plot(xy[:, 0], xy[:, 1], color=SETTING_COLOURS[setting], lw=1, label=setting)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.legend(fontsize=8)
        ax.set_title(f"{ev.algorithm} on {sequence}")
    return out_png


def aligned_positions(gt: np.ndarray, est: np.ndarray) -> np.ndarray:
    """(N, 3) positions of ``est`` (N, 4, 4) started at the ground truth's first pose."""
    return (gt[0] @ np.linalg.inv(est[0]) @ est)[:, :3, 3]


def trials_figure(rows: list[dict[str, Any]], names: Sequence[str], out_png: Path) -> Path:
    """The first two parameters of every trial, one panel per study, coloured by its RTE.

    rows: trials table rows (sequence, status, objective, p_<name>); failed trials are crosses.
    """
    studies = sorted({r["sequence"] for r in rows})
    ncols = min(4, max(1, len(studies)))
    nrows = math.ceil(len(studies) / ncols)
    x_name, y_name = (names[0], names[1]) if len(names) > 1 else (names[0], names[0])
    ok = [r["objective"] for r in rows if r["status"] == "ok"]
    vmin, vmax = (min(ok), max(ok)) if ok else (0.1, 1.0)
    with figure(out_png, nrows, ncols, (3.2 * ncols + 1, 3.0 * nrows + 0.4)) as (fig, axes):
        import matplotlib.colors as mcolors

        norm = mcolors.LogNorm(vmin=max(vmin, 1e-3), vmax=max(vmax, vmin * 1.01, 1e-3))
        sc = None
        for ax, study in zip(axes.flat, studies, strict=False):
            mine = [r for r in rows if r["sequence"] == study]
            good = [r for r in mine if r["status"] == "ok"]
            bad = [r for r in mine if r["status"] != "ok"]
            sc = ax.scatter([r[f"p_{x_name}"] for r in good], [r[f"p_{y_name}"] for r in good],
                            c=[r["objective"] for r in good], norm=norm, cmap="viridis_r", s=10)
            ax.scatter([r[f"p_{x_name}"] for r in bad], [r[f"p_{y_name}"] for r in bad],
                       marker="x", color="tab:red", s=10)
            if good:
                best = min(good, key=lambda r: r["objective"])
                ax.plot(best[f"p_{x_name}"], best[f"p_{y_name}"], "r*", ms=12)
            ax.set_title(study, fontsize=9)
            ax.set_xlabel(x_name, fontsize=8)
            ax.set_ylabel(y_name, fontsize=8)
        for ax in list(axes.flat)[len(studies):]:
            ax.set_visible(False)
        if sc is not None:
            fig.colorbar(sc, ax=axes.ravel().tolist(), label="mean RTE [%]")
        fig.suptitle("SMBO samples per training sequence (x: failed, *: best)")
    return out_png
