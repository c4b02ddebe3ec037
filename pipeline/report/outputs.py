"""What every stage that reports writes with: JSON that keeps NaN out, metrics apart from their
record (``write_metrics``), CSV plot data, PNG figures (matplotlib, Agg backend, written
atomically) and the settings' colours.

Metrics and record (docs/design.md, "Formats"): a stage's summary is one nested dict; its
*figures* (errors, ratios, counts of what the method did) go to ``metrics/<stage>.json``, the
file ``dvc metrics`` / ``dvc exp show`` read, and everything else (what ran: names, sizes,
params echoed, wall times, trial counts, raw per-run lists) to ``records/<stage>.json``, a
plain output. So ``dvc metrics diff`` of two runs of the same code shows figures only.
``split_leaves`` cuts a summary in two, ``merge_leaves`` puts it back together.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.io_utils import atomic_path, atomic_write_text

SETTING_COLOURS = {"ground truth": "black", "baseline": "tab:gray", "fixed": "tab:orange",
                   "adaptive": "tab:red"}


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as null and numpy scalars as Python numbers."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, value: Any) -> None:
    """``value`` (``json_safe``) as indented JSON at ``path``, atomically."""
    atomic_write_text(path, json.dumps(json_safe(value), indent=2) + "\n")


def is_record_leaf(key: str, value: Any, record_keys: Collection[str]) -> bool:
    """Whether a summary's leaf ``key: value`` is bookkeeping: named in ``record_keys``, or
    text (a string or a list of strings: never a figure)."""
    if key in record_keys or isinstance(value, str):
        return True
    return isinstance(value, list) and bool(value) and all(isinstance(v, str) for v in value)


def split_leaves(summary: Mapping[str, Any], record_keys: Collection[str]
                 ) -> tuple[dict[str, Any], dict[str, Any]]:
    """(figures, record) of a nested ``summary``: every key whose subtree or leaf is
    bookkeeping (``is_record_leaf``) goes to the record, the rest to the figures, both keeping
    the nesting (a branch left empty is dropped). ``merge_leaves`` inverts it."""
    figures: dict[str, Any] = {}
    record: dict[str, Any] = {}
    for key, value in summary.items():
        if is_record_leaf(str(key), value, record_keys):
            record[key] = value
        elif isinstance(value, Mapping) and value:
            f, r = split_leaves(value, record_keys)
            if f:
                figures[key] = f
            if r:
                record[key] = r
        else:
            figures[key] = value
    return figures, record


def merge_leaves(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    """The nested union of ``a`` and ``b`` (a summary from its figures and record; the keys
    in ``a``'s order first); ValueError when both hold the same leaf."""
    out = dict(a)
    for key, value in b.items():
        if key not in out:
            out[key] = value
        elif isinstance(out[key], Mapping) and isinstance(value, Mapping):
            out[key] = merge_leaves(out[key], value)
        else:
            raise ValueError(f"{key!r} is in both the metrics and the record")
    return out


def write_metrics(metrics_path: Path, record_path: Path, summary: Mapping[str, Any],
                  record_keys: Collection[str]) -> None:
    """``summary`` split (``split_leaves``): its figures as JSON at ``metrics_path``, its
    record at ``record_path``, each written atomically."""
    figures, record = split_leaves(json_safe(summary), record_keys)
    write_json(metrics_path, figures)
    write_json(record_path, record)


def record_beside(metrics_path: Path) -> Path:
    """Where the record of ``<dir>/metrics/<name>.json`` is: ``<dir>/records/<name>.json``
    (dvc.yaml's layout, and ``make kitti``'s copies)."""
    return Path(metrics_path).parent.parent / "records" / Path(metrics_path).name


def read_summary(metrics_path: Path, record_path: Path | None = None) -> dict[str, Any]:
    """The summary a stage wrote with ``write_metrics``: its metrics and its record (by
    default the one ``record_beside`` them) together; InputError naming an unreadable file."""
    from pipeline.io_utils import read_input_text

    if record_path is None:
        record_path = record_beside(metrics_path)
    parts = []
    from pipeline.json_yaml import parse_json

    for path in (metrics_path, record_path):
        parts.append(parse_json(read_input_text(path, "metrics JSON", strict=True), str(path)))
    return merge_leaves(parts[0], parts[1])


def csv_text(rows: list[dict[str, Any]], header: Sequence[str] = ("frame",)) -> str:
    """``rows`` (dicts with the same keys) as CSV text, a header line first (the keys of the
    first row; ``header`` when there is none)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else list(header),
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


@contextmanager
def figure(out_png: Path, nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (9, 4),
            **kw: Any) -> Iterator[tuple[Any, Any]]:
    """A matplotlib figure saved to ``out_png`` (atomically) and closed on exit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(nrows, ncols, figsize=size, dpi=110, squeeze=False,
                             layout="constrained", **kw)
    try:
        yield fig, axes
        with atomic_path(out_png) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
