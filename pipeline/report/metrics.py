"""The ``evaluate`` stage's summary: RTE per setting, split, label and sequence, the ratios, the
devkit metric, replica runs, trial counts. ``metrics/evaluation.json`` holds its figures,
``records/evaluation.json`` the rest (``RECORD_KEYS``; ``pipeline.outputs``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pipeline.evaluate.result import SETTINGS, Evaluation

RECORD_KEYS = ("length_m", "replicas", "kitti_lengths_m", "segments", "wall_time_s", "params",
               "trials", "replicas_rte_pct", "warning_text")
"""The summary's bookkeeping (besides its text): params echoed, segment counts, wall times,
the parameters baseline and fixed ran with, trial counts, the replica runs' raw lists, the
warnings' sentences (their flags, ``warnings``, are metrics: ``pipeline.report.checks``)."""


def trials_summary(studies: Mapping[str, Path]) -> dict[str, dict[str, float]]:
    """Trial counts by status (failed: the odometry failed; pruned: stopped early as hopeless;
    lost: to the machinery) of every SMBO output folder (their wall times: the trials stages'
    records)."""
    from pipeline.tuning.layout import read_trials_tables

    out = {}
    for study, folder in studies.items():
        rows = read_trials_tables(folder).to_pylist()
        out[study] = {"studies": len({(r["algorithm"], r["sequence"]) for r in rows}),
                      "trials": len(rows),
                      **{status: sum(r["status"] == status for r in rows)
                         for status in ("failed", "pruned", "lost")}}
    return out


def _ratio(values: Mapping[str, float]) -> dict[str, float]:
    return {"adaptive_vs_baseline": values["adaptive"] / values["baseline"],
            "adaptive_vs_fixed": values["adaptive"] / values["fixed"]}


def split_metrics(ev: Evaluation, split: str) -> dict[str, Any]:
    """The figures of one split: its sequences, RTE [%] pooled (overall, per label), the
    ratios, and the devkit metric pooled over the split's segments with its ratios."""
    rte = {s: ev.overall(s, split) for s in SETTINGS}
    kitti = {s: ev.kitti_split(s, split) for s in SETTINGS}
    out = {"sequences": ev.in_split(split), "rte_pct": rte, "ratio": _ratio(rte),
           "rte_pct_per_label": {s: ev.overall_per_label(s, split) for s in SETTINGS},
           "kitti": kitti,
           "kitti_ratio": _ratio({s: k["t_err_pct"] for s, k in kitti.items()})}
    if ev.replicas:
        out["replicas"] = {s: ev.replica_runs(s, split) for s in SETTINGS}
    return out


def metrics(ev: Evaluation, trials: Mapping[str, Mapping[str, float]]) -> dict[str, Any]:
    """The stage's summary: RTE per setting (headline split: overall, per label; per split;
    per sequence), ratios, KITTI metric, failed-trial counts and wall times."""
    splits = {split: split_metrics(ev, split) for split in ev.splits}
    head = splits[ev.splits[0]]
    return {
        "algorithm": ev.algorithm,
        "length_m": ev.length_m,
        "replicas": ev.replicas,
        "headline_split": ev.splits[0],
        "kitti_lengths_m": list(ev.kitti_lengths_m),
        "rte_pct": head["rte_pct"],
        "ratio": head["ratio"],
        "rte_pct_per_label": head["rte_pct_per_label"],
        "splits": splits,
        "sequences": {name: {
            "split": ev.split_of[name],
            "rte_pct": {s: ev.score(s, name).rte_pct for s in SETTINGS},
            "rte_pct_per_label": {s: ev.score(s, name).per_label() for s in SETTINGS},
            "kitti": ev.kitti[name],
            "wall_time_s": {s: ev.score(s, name).wall_time_s for s in SETTINGS},
            "parameter_changes": ev.schedules[name].n_changes,
            **({"length_m": ev.infos[name].length_m}  # its own RTE length (the record's)
               if ev.infos[name].length_m is not None else {}),
            **({"replicas_rte_pct": {s: ev.score(s, name).replica_rte_pct for s in SETTINGS}}
               if ev.replicas else {}),
        } for name in ev.sequences},
        "params": {"baseline": ev.baseline_params, "fixed": ev.fixed_params},
        "trials": dict(trials),
    }
