"""A KITTI data set for the pipeline: the ``ingest`` stage's counterpart of ``simulate``.

``ingest_kitti_set`` writes ``<out>/<NN>.mcap`` for every KITTI sequence named in the params
section ``ingest`` and ``<out>/index.json`` ({"train": [...], "validation": [...]}), the same
layout the ``simulate`` stage writes, so every later stage reads either. With no KITTI root
configured it writes an empty index (the toy pipeline then runs on the simulated worlds).
"""

from __future__ import annotations

import logging
from pathlib import Path

from pydantic import Field, model_validator

from pipeline.config import Section
from pipeline.io_utils import output_folder
from pipeline.sequence_index import check_split, write_index
from pipeline.sources.base import IngestReport
from pipeline.sources.kitti import ingest_kitti

log = logging.getLogger(__name__)


class IngestSection(Section):
    """params.yaml ``ingest``: KITTI odometry sequences (``ROOT/sequences/NN``) and their split.

    start / end: KITTI frame numbers (end inclusive) applied to every sequence; null = all.
    """

    kitti_root: str | None = None
    train: list[str] = Field(default_factory=list)
    validation: list[str] = Field(default_factory=list)
    start: int | None = Field(None, ge=0)
    end: int | None = Field(None, ge=0)

    @model_validator(mode="after")
    def _consistent(self) -> IngestSection:
        check_split("kitti_root", self.kitti_root, self.train, self.validation)
        if self.start is not None and self.end is not None and self.end < self.start:
            raise ValueError(f"end must be >= start, got (start={self.start}, end={self.end})")
        return self


def ingest_kitti_set(section: IngestSection, out_dir: str | Path) -> list[IngestReport]:
    """Ingest the configured KITTI sequences into ``out_dir`` (module docstring)."""
    out_dir = Path(out_dir)
    output_folder(out_dir)
    reports = []
    if section.kitti_root is None:
        log.info("ingest: no kitti_root configured, writing an empty data set")
    else:
        for seq in [*section.train, *section.validation]:
            reports.append(ingest_kitti(section.kitti_root, seq, out_dir / f"{seq}.mcap",
                                        section.start, section.end, name=seq))
    index = {"train": list(section.train), "validation": list(section.validation)}
    write_index(out_dir, index)
    return reports
