"""Ingest throughput: raw KITTI .bin scans into a sequence MCAP, beside merely reading them.

On kitti_mini (4 sequences x 10 scans, ~2 MB each): MB/s of raw scan bytes through
`ingest_kitti` (read, check, zstd-compress, index, write) and through np.fromfile alone.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from common import Row, best_of, data_root, size

from pipeline.sources import ingest_kitti

SEQUENCES = size(("01", "04", "06", "10"), ("04",))


def run() -> list[Row]:
    root = data_root() / "kitti_mini" / "dataset"
    bins = [
        b for s in SEQUENCES for b in sorted((root / "sequences" / s / "velodyne").glob("*.bin"))
    ]
    mb = sum(b.stat().st_size for b in bins) / 1e6

    def read_only() -> None:
        for b in bins:
            np.fromfile(b, np.float32).reshape(-1, 4)

    with tempfile.TemporaryDirectory() as tmp:

        def ingest() -> None:
            for s in SEQUENCES:
                ingest_kitti(root, s, Path(tmp) / f"{s}.mcap")

        t_read = best_of(read_only, repeat=5)
        t_ingest = best_of(ingest, repeat=3)
        mcap_mb = sum(p.stat().st_size for p in Path(tmp).glob("*.mcap")) / 1e6
    n = len(bins)
    return [
        Row(
            "ingest KITTI .bin -> sequence MCAP",
            mb / t_ingest,
            "MB/s",
            f"np.fromfile alone: {mb / t_read:.0f} MB/s",
            "reported (issue 2)",
        ),
        Row(
            "ingest time per scan",
            1e3 * t_ingest / n,
            "ms",
            f"read alone: {1e3 * t_read / n:.2f} ms ({n} scans, {mb:.0f} MB)",
            "",
        ),
        Row("sequence MCAP size / raw .bin size", mcap_mb / mb, "ratio", "zstd, chunked", ""),
    ]
