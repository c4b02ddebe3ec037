"""Summary of a sequence MCAP (``adaptune info``): frames, duration, path length, points."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import InputError
from pipeline.geometry import path_distances
from pipeline.ros2_cdr import decode_pointcloud2
from pipeline.sequence import POINTS_TOPIC, SequenceReader


@dataclass(frozen=True)
class SequenceSummary:
    """What ``adaptune info`` prints. ``path_length_m`` is None without ground truth;
    ``points_per_scan`` has min / median / max; labels are [start, end, label] frame ranges."""

    path: str
    name: str
    frames: int
    duration_s: float
    path_length_m: float | None
    has_ground_truth: bool
    points_per_scan: dict[str, float]
    sensor: str
    source: str
    labels: list[list[Any]] = field(default_factory=list)
    schema_version: str = ""
    details: dict[str, str] = field(default_factory=dict)
    """The source's own records: intensity scaling, per-point time, stamps, simulation, the
    run a piece comes from, an RTE length and a jump limit of its own (``rte_length``,
    ``jump_limit``)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def summarize_sequence(path: str | Path) -> SequenceSummary:
    """Summarise the sequence MCAP at ``path`` (reads the scan headers, not the points)."""
    path = Path(path)
    with SequenceReader(path) as reader:
        gt = reader.ground_truth()
        counts = _points_per_scan(reader)
        stamps = reader.stamps_ns
        info = reader.info
        return SequenceSummary(
            path=str(path),
            name=info.name,
            frames=len(reader),
            duration_s=float(stamps[-1] - stamps[0]) / 1e9 if len(stamps) else 0.0,
            path_length_m=None if gt is None else float(path_distances(gt)[-1]),
            has_ground_truth=gt is not None,
            points_per_scan={
                "min": int(counts.min()),
                "median": float(np.median(counts)),
                "max": int(counts.max()),
            },
            sensor=info.sensor,
            source=info.source,
            labels=[[lab.start, lab.end, lab.label] for lab in info.labels],
            details={**info.extra, **{what: f"{value:g} m (its own)" for what, value in
                                      (("rte_length", info.length_m),
                                       ("jump_limit", info.jump_limit_m)) if value is not None}},
            schema_version=info.schema_version,
        )


def _points_per_scan(reader: SequenceReader) -> np.ndarray:
    """(frames,) point counts from the PointCloud2 headers (width x height), read through
    every chunk of the file: `info` checks every chunk's CRC (``iter_every_chunk``)."""
    counts: list[int] = []
    for topic, msg in reader.iter_every_chunk():
        if topic == POINTS_TOPIC:
            m = decode_pointcloud2(msg.data, f"{reader.path} frame {len(counts)}")
            counts.append(m.width * m.height)
    if len(counts) != len(reader) or not counts:
        raise InputError(f"{reader.path}: {len(counts)} point clouds for {len(reader)} frames")
    return np.array(counts, np.int64)
