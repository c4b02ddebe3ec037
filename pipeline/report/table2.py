"""The paper's Table II: the KITTI devkit error per sequence, per split and per algorithm.

One block per algorithm, one row per setting (baseline, fixed, adaptive), one column per
sequence grouped by split (training sequences first), each split followed by its average: the
devkit t_err [%] pooled over every segment of the split's sequences, as the devkit pools a
benchmark. The input is the ``evaluate`` stage's summary (``pipeline.report.metrics.metrics``:
its metrics JSON and its record) of each algorithm; ``table2_json`` and ``table2_markdown`` lay
them out.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pipeline.errors import InputError
from pipeline.evaluate.result import SETTINGS

SPLIT_TITLES = {"train": "training"}
"""How a split is named in the table's headers (others by their own name)."""


def split_order(metrics: Mapping[str, Any]) -> list[str]:
    """The evaluated splits of one metrics JSON, ``train`` first (the paper's order)."""
    splits = list(metrics.get("splits") or {})
    return sorted(splits, key=lambda s: s != "train")


def table2_json(blocks: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """{"length_m", "algorithms": {algorithm: {"sequences": {name: {"split", "segments",
    "t_err_pct": {setting: v}}}, "averages": {split: {"t_err_pct": {setting: v},
    "segments"}}, "params": {...}}}} of the metrics JSONs ``blocks``; InputError when one is
    not an ``evaluate`` metrics JSON or two disagree on L or on the sequences."""
    out: dict[str, Any] = {"length_m": None, "algorithms": {}}
    layout = None
    for m in blocks:
        _check(m)
        if out["length_m"] not in (None, m["length_m"]):
            raise InputError(f"metrics of {m['algorithm']!r}: L = {m['length_m']} m, the "
                             f"others {out['length_m']} m")
        out["length_m"] = m["length_m"]
        mine = {s: m["splits"][s]["sequences"] for s in split_order(m)}
        if layout is not None and mine != layout:
            raise InputError(f"metrics of {m['algorithm']!r}: sequences {mine}, the others "
                             f"{layout}")
        layout = mine
        out["algorithms"][m["algorithm"]] = {
            "sequences": {name: {"split": seq["split"],
                                 "segments": seq["kitti"]["baseline"]["segments"],
                                 "t_err_pct": {s: seq["kitti"][s]["t_err_pct"] for s in SETTINGS}}
                          for name, seq in m["sequences"].items()},
            "averages": {split: {"t_err_pct": {s: m["splits"][split]["kitti"][s]["t_err_pct"]
                                               for s in SETTINGS},
                                 "segments": m["splits"][split]["kitti"]["baseline"]["segments"]}
                         for split in mine},
            "params": m.get("params", {}),
            "replicas": {split: {s: m["splits"][split]["replicas"][s]["kitti_t_err_pct"]
                                 for s in SETTINGS}
                         for split in mine if "replicas" in m["splits"][split]},
        }
    out["splits"] = layout or {}
    return out


def _check(m: Mapping[str, Any]) -> None:
    keys = ("algorithm", "length_m", "splits", "sequences")
    if not isinstance(m, Mapping) or any(k not in m for k in keys):
        raise InputError("not the summary of the evaluate stage (its metrics and record need "
                         f"{', '.join(keys)})")


def _fmt(v: float | None) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.2f}"


def table2_markdown(table: Mapping[str, Any],
                    split_titles: Mapping[str, str] | None = None) -> str:
    """The markdown table of ``table2_json``: per algorithm and setting, the devkit t_err [%]
    of every sequence and the average of every split; the best setting of each column in
    bold."""
    titles = {**SPLIT_TITLES, **dict(split_titles or {})}
    columns: list[tuple[str, str, str]] = []  # (header, "sequences" | "averages", key)
    for split, names in table["splits"].items():
        columns += [(n, "sequences", n) for n in names]
        columns.append((f"{titles.get(split, split)} avg", "averages", split))
    head = ["algorithm", "setting", *[h for h, _, _ in columns]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for algorithm, block in table["algorithms"].items():
        cells: dict[str, list[str]] = {s: [] for s in SETTINGS}
        for _, kind, key in columns:
            vals = {s: block[kind][key]["t_err_pct"][s] for s in SETTINGS}
            finite = [v for v in vals.values() if v is not None and math.isfinite(v)]
            best = min(finite) if finite else None
            for s in SETTINGS:
                text = _fmt(vals[s])
                cells[s].append(f"**{text}**" if best is not None and vals[s] == best else text)
        for i, s in enumerate(SETTINGS):
            lines.append(f"| {algorithm if i == 0 else ''} | {s} | " + " | ".join(cells[s]) + " |")
    return "\n".join(lines) + "\n" + replicas_markdown(table, titles)


def replicas_markdown(table: Mapping[str, Any], titles: Mapping[str, str]) -> str:
    """The spread of every split's average over the nominal and replica runs of each setting
    (``evaluate.replicas``): median [min, max]; empty without replicas."""
    blocks = {a: b["replicas"] for a, b in table["algorithms"].items() if b.get("replicas")}
    if not blocks:
        return ""
    splits = list(table["splits"])
    head = ["algorithm", "runs", "setting", *[f"{titles.get(s, s)} avg" for s in splits]]
    lines = ["", "Spread over the runs (the nominal one and replicas with every parameter "
             "moved by at most `evaluate.replica_scale`): median [min, max] of each split's "
             "average; failed runs left out.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for algorithm, reps in blocks.items():
        for i, s in enumerate(SETTINGS):
            runs = len(next(iter(reps.values()))[s])
            cells = [_spread(reps[split][s]) if split in reps else "-" for split in splits]
            lines.append(f"| {algorithm if i == 0 else ''} | {runs if i == 0 else ''} | {s} | "
                         + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _spread(values: Sequence[float | None]) -> str:
    """"median [min, max]" of the finite values; "-" without any."""
    ok = sorted(v for v in values if v is not None and math.isfinite(v))
    if not ok:
        return "-"
    return f"{statistics.median(ok):.3f} [{ok[0]:.3f}, {ok[-1]:.3f}]"


KITTI_SPLIT_TITLES = {"train": "training", "validation": "test"}
"""The KITTI protocol's names of the index splits (its test sequences are ``validation``)."""


def write_table2(metrics_paths: Sequence[Path], out_dir: Path,
                 split_titles: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Read the ``evaluate`` summary of every algorithm (each metrics JSON with the record
    ``pipeline.outputs.record_beside`` it), write ``out_dir``/table.json and table.md
    (atomically); return the table. InputError for a file that is not one."""
    from pipeline.io_utils import atomic_write_text
    from pipeline.outputs import read_summary, write_json

    blocks = [read_summary(path) for path in metrics_paths]
    if not blocks:
        raise InputError("no metrics JSON given")
    table = table2_json(blocks)
    lengths = ", ".join(f"{x:g}" for x in blocks[0].get("kitti_lengths_m", []))
    md = ("# KITTI protocol (the paper's Table II)\n\n"
          f"KITTI devkit t_err [%] (segments of {lengths} m that fit); a split's average pools "
          f"every segment of its sequences; SMBO objective L = {table['length_m']:g} m; the "
          "best setting of each column in bold.\n\n"
          + table2_markdown(table, split_titles))
    write_json(out_dir / "table.json", table)
    atomic_write_text(out_dir / "table.md", md)
    return table
