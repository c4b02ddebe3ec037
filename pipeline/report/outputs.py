"""What every stage that reports writes with: JSON that keeps NaN out, CSV plot data, PNG figures
(matplotlib, Agg backend, written atomically) and the settings' colours."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterator, Mapping
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


def csv_text(rows: list[dict[str, Any]]) -> str:
    """``rows`` (dicts with the same keys) as CSV text, a header line first."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["frame"],
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
