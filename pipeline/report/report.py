"""The ``evaluate`` stage's outputs: metrics JSON, plot data for ``dvc plots``, report.md + PNGs.

``run_evaluation`` reads like the stage's table of contents: take the fixed parameters from the
joint SMBO, run and score the three settings (``pipeline.evaluate``), then write the
metrics, the plot data and the report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.artifact import read_manifest
from pipeline.evaluate.result import SETTINGS, Evaluation
from pipeline.evaluate.runs import best_fixed_params, evaluate
from pipeline.evaluate.section import EvaluateSection
from pipeline.io_utils import atomic_write_text
from pipeline.outputs import csv_text, write_metrics
from pipeline.report import figures
from pipeline.report.checks import evaluation_warnings, warning_lines
from pipeline.report.metrics import RECORD_KEYS, metrics, trials_summary
from pipeline.report.table2 import table2_json, table2_markdown


@dataclass(frozen=True)
class EvaluationPaths:
    """Inputs and outputs of the ``evaluate`` stage (all from dvc.yaml)."""

    sequences: Path  # data/sequences (index.json + MCAPs)
    trials: Path  # results/trials (per-sequence SMBO)
    fixed: Path  # results/fixed (joint SMBO)
    adaptive: Path  # results/adaptive
    runs: Path  # results/evaluation: baseline and fixed trajectories
    metrics: Path  # metrics/evaluation.json (the figures)
    record: Path  # records/evaluation.json (the rest of the summary)
    plots: Path  # plots/ (CSV for dvc plots)
    report: Path  # report/ (report.md + PNG)
    model: Path | None = None  # model/: its cross-validation for the warnings (None: unknown)


def run_evaluation(paths: EvaluationPaths, settings: EvaluateSection) -> dict[str, Any]:
    """Evaluate baseline, fixed and adaptive on the sequences of ``settings.splits``; write
    everything; return the summary (metrics and record together)."""
    from pipeline.sequence_index import read_index
    from pipeline.tuning.layout import read_trials_tables

    algorithm, fixed = best_fixed_params(paths.fixed)
    split_of = read_index(paths.sequences).split_paths(settings.splits)
    ev = evaluate(list(split_of), algorithm, fixed, paths.adaptive, paths.runs, settings,
                  paths.fixed, {p.stem: split for p, split in split_of.items()})
    result = metrics(ev, trials_summary({"trials": paths.trials, "fixed": paths.fixed}))
    cv = None if paths.model is None else read_manifest(paths.model)["cross_validation"]
    result["warnings"] = evaluation_warnings(result, cv)
    result["warning_text"] = warning_lines(result, cv)
    write_metrics(paths.metrics, paths.record, result, RECORD_KEYS)
    write_plot_data(ev, paths.plots)
    trial_rows = [r for r in read_trials_tables(paths.trials).to_pylist()
                  if r["algorithm"] == algorithm]
    pngs = write_figures(ev, trial_rows, paths.report)
    atomic_write_text(paths.report / "report.md", report_markdown(ev, result, pngs))
    return result


# ----------------------------------------------------------------------------- plot data


def _num(v: float) -> float | str:
    return round(float(v), 6) if math.isfinite(v) else ""


def write_plot_data(ev: Evaluation, plots_dir: Path) -> None:
    """CSV files for ``dvc plots show`` (dvc.yaml ``plots``), all validation sequences:
    schedule/<parameter>.csv (per frame: the adaptive value, the fixed and the baseline one;
    one file a parameter, so the plot definition fits every algorithm), rte_frames.csv
    (per-start-frame RTE of every setting), trajectory_<setting>.csv (x_m, y_m, started at the
    true first pose)."""
    sched: dict[str, list[dict[str, Any]]] = {n: [] for n in ev.baseline_params}
    rte = []
    traj: dict[str, list[dict[str, Any]]] = {"ground_truth": [], **{s: [] for s in SETTINGS}}
    for name in ev.sequences:
        stamps = ev.score("adaptive", name).trajectory.stamps_ns
        t_s = (stamps - stamps[0]) * 1e-9
        labels = [ev.infos[name].label_of(i) or "" for i in range(len(stamps))]
        s = ev.schedules[name]
        gt = ev.ground_truth[name]
        errs = {k: ev.score(k, name).t_err_pct for k in SETTINGS}
        for i in range(len(stamps)):
            base = {"sequence": name, "frame": i, "time_s": round(float(t_s[i]), 3),
                    "label": labels[i]}
            for n, v in s.values.items():
                sched[n].append({**base, "adaptive": float(v[i]), "fixed": ev.fixed_params[n],
                                 "baseline": ev.baseline_params[n]})
            rte.append({**base, **{k: _num(e[i]) for k, e in errs.items()}})
        xy = {"ground_truth": gt[:, :3, 3],
              **{k: figures.aligned_positions(gt, ev.score(k, name).trajectory.T_world_lidar)
                 for k in SETTINGS}}
        for k, pos in xy.items():
            traj[k] += [{"sequence": name, "frame": i, "x_m": round(float(p[0]), 4),
                         "y_m": round(float(p[1]), 4)} for i, p in enumerate(pos)]
    for n, rows in sched.items():
        atomic_write_text(plots_dir / "schedule" / f"{n}.csv", csv_text(rows))
    atomic_write_text(plots_dir / "rte_frames.csv", csv_text(rte))
    for k, rows in traj.items():
        atomic_write_text(plots_dir / f"trajectory_{k}.csv", csv_text(rows))


# -------------------------------------------------------------------------------- report


def write_figures(ev: Evaluation, trial_rows: list[dict[str, Any]],
                  report_dir: Path) -> dict[str, list[Path]]:
    """Every PNG of the report, in ``report_dir``/figures: kind -> files (relative to
    ``report_dir``)."""
    from pipeline.sim.plot import plot_world
    from pipeline.sim.simulate import spec_of

    out: dict[str, list[Path]] = {"world": [], "schedule": [], "rte": [], "trajectory": [],
                                  "trials": []}
    fig_dir = report_dir / "figures"
    for name in ev.sequences:
        spec = spec_of(ev.infos[name])
        if spec is not None:  # a simulated world: its top view, trajectory and one scan
            out["world"].append(plot_world(spec, fig_dir / f"world_{name}.png"))
        out["schedule"].append(figures.schedule_figure(ev, name, fig_dir / f"schedule_{name}.png"))
        out["rte"].append(figures.rte_figure(ev, name, fig_dir / f"rte_{name}.png"))
        out["trajectory"].append(
            figures.trajectory_figure(ev, name, fig_dir / f"trajectory_{name}.png"))
    names = list(ev.baseline_params)
    if trial_rows:
        out["trials"].append(figures.trials_figure(trial_rows, names, fig_dir / "trials.png"))
    return {k: [p.relative_to(report_dir) for p in v] for k, v in out.items()}


def _fmt(v: float | None, digits: int = 3) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def _own_lengths(ev: Evaluation) -> str:
    """" (seq_a: 10 m, ...)": the sequences scored at an RTE length of their own ("": none)."""
    own = [f"{n}: {i.length_m:g} m" for n, i in ev.infos.items() if i.length_m is not None]
    return f" (those of a length of their own at it: {', '.join(own)})" if own else ""


def _params(p: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {v:.3g}" for k, v in p.items())


def report_markdown(ev: Evaluation, m: Mapping[str, Any], pngs: Mapping[str, list[Path]]) -> str:
    """report.md: the paper-style table, the parameters, trial counts and the figures."""
    labels = list(dict.fromkeys(lab for s in SETTINGS for lab in m["rte_pct_per_label"][s]))
    head = ["method", *labels, "overall"]
    head_split = m["headline_split"]
    warned = [f"> **Warning**: {line}." for line in m.get("warning_text", [])]
    lines = [
        f"# adaptune: baseline vs fixed vs adaptive ({ev.algorithm})",
        "",
        *[part for line in warned for part in (line, "")],
        f"Split {head_split!r}: {', '.join(ev.in_split(head_split))}. Mean translational RTE "
        f"[%] of {ev.length_m:g} m sub-trajectories{_own_lengths(ev)}, one starting at every "
        "frame; a segment counts for the environment of its start frame; all sequences of the "
        "split pooled.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for s in SETTINGS:
        per = m["rte_pct_per_label"][s]
        cells = [s, *(_fmt(per.get(lab)) for lab in labels), f"**{_fmt(m['rte_pct'][s])}**"]
        lines.append("| " + " | ".join(cells) + " |")
    r = m["ratio"]
    lines += [
        "",
        f"adaptive / baseline = {_fmt(r['adaptive_vs_baseline'], 2)}, "
        f"adaptive / fixed = {_fmt(r['adaptive_vs_fixed'], 2)} "
        "(paper, toy world, NDT: 0.69 and 0.70).",
        "",
        f"- baseline parameters: {_params(m['params']['baseline'])}",
        f"- fixed parameters (best of the joint SMBO): {_params(m['params']['fixed'])}",
        "- adaptive: chosen online every period from the newest scan (figures below)",
        "",
        *_per_split(m),
        "## KITTI devkit metric (the paper's Table II layout)",
        "",
        "t_err [%] of the devkit (segments of "
        f"{', '.join(f'{x:g}' for x in ev.kitti_lengths_m)} m that fit, a start every "
        f"{ev.kitti_step_frames} frames); "
        "a split's average pools all its segments.",
        "",
        table2_markdown(table2_json([m])),
        "## Per sequence",
        "",
        "| sequence | setting | RTE [%] | KITTI t_err [%] | KITTI r_err [deg/100 m] | segments |",
        "|---|---|---|---|---|---|",
    ]
    for name, seq in m["sequences"].items():
        for s in SETTINGS:
            k = seq["kitti"][s]
            lines.append(f"| {name} | {s} | {_fmt(seq['rte_pct'][s])} | {_fmt(k['t_err_pct'])} "
                         f"| {_fmt(k['r_err_deg_per_100m'])} | {k['segments']} |")
    lines += ["", "## Trials", "", "| study | studies | trials | failed | pruned |",
              "|---|---|---|---|---|"]
    for study, t in m["trials"].items():
        lines.append(f"| {study} | {t['studies']} | {t['trials']} | {t['failed']} "
                     f"| {t.get('pruned', 0)} |")
    captions = {"world": "The validation world from above: trajectory by environment, one scan",
                "schedule": "Parameters chosen online (environment shaded; cf. paper Fig. 5)",
                "rte": "Per-start-frame RTE", "trajectory": "Trajectories (top view)",
                "trials": "SMBO samples per training sequence (cf. paper Fig. 4 and 6)"}
    lines += ["", "## Figures", ""]
    for kind, files in pngs.items():
        lines += [f"![{captions[kind]}]({f.as_posix()})\n" for f in files]
    return "\n".join(lines) + "\n"


def _per_split(m: Mapping[str, Any]) -> list[str]:
    """The RTE table of every evaluated split (none when only one split is evaluated)."""
    if len(m["splits"]) < 2:
        return []
    lines = ["## Per split", "", "| split | sequences | " + " | ".join(SETTINGS)
             + " | adaptive / baseline | adaptive / fixed |", "|---|---|---|---|---|---|---|"]
    for split, sm in m["splits"].items():
        lines.append(f"| {split} | {', '.join(sm['sequences'])} | "
                     + " | ".join(_fmt(sm["rte_pct"][s]) for s in SETTINGS)
                     + f" | {_fmt(sm['ratio']['adaptive_vs_baseline'], 2)}"
                     f" | {_fmt(sm['ratio']['adaptive_vs_fixed'], 2)} |")
    return [*lines, ""]
