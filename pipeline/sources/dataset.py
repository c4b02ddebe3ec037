"""Your recordings as the pipeline's data set: the params section ``data`` and the ingest stage.

``data.sources`` lists recordings, each a mapping: its ``kind`` (a source of
``pipeline.sources.SOURCES``), its ``path``, its ``split`` (train, validation or test) and its
options, one to one those of ``adaptune ingest <kind>`` (with underscores for dashes):

- ``rosbag`` (a ROS 1 .bag or a ROS 2 bag folder) and ``mcap``: topic, the ground truth
  (``GroundTruthOptions``: gt_topic, gt_child_frame, poses, poses_format, extrinsic), name,
  sensor, intensity;
- ``folder`` (scan files .bin / .pcd / .ply): the ground truth's poses, poses_format and
  extrinsic, times, rate_hz, name, sensor, intensity;
- ``kitti``: ``path`` a KITTI odometry root, ``sequences`` (one MCAP each, named as KITTI names
  them: ``04``), start, end (KITTI frame numbers, end inclusive), name (one sequence only).

Relative paths (path, poses, times, an extrinsic file) are relative to the folder of the params
file, not the working directory, and ``~`` is the home folder. ``ingest_data_set`` checks
every recording first (layout, topics, ground truth, unique names, and that its ground truth
runs longer than base.length_m: ``check_length``), then writes
``<out>/<name>.mcap`` for each and ``<out>/index.json`` ({"train": [...], "validation": [...],
"test": [...]}; test only when a recording is in it), the layout the ``simulate`` stage writes,
so every later stage reads either. With no sources it writes an empty index.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.errors import ConfigError, InputError
from pipeline.io_utils import check_plain_name, output_folder
from pipeline.sequence_index import write_index
from pipeline.sources.base import IngestReport, IntensityMode, Source, write_sequence
from pipeline.sources.poses import GroundTruthOptions, resolve_path

log = logging.getLogger(__name__)

Split = Literal["train", "validation", "test"]
SPLITS: tuple[str, ...] = ("train", "validation", "test")
NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$"
"""A sequence name is the stem of its MCAP file: letters, digits, ``_``, ``.``, ``-``."""


class _Entry(Section):
    """What every source of ``data.sources`` has: its input, its split, its name."""

    path: str = Field(min_length=1)
    split: Split = "train"
    name: str | None = Field(None, pattern=NAME_PATTERN)

    PATHS: ClassVar[tuple[str, ...]] = ("path",)
    """The fields that are paths (relative ones are relative to the params file)."""

    def resolved(self, base_dir: Path) -> Any:
        """A copy with every path absolute (relative ones from ``base_dir``)."""
        update = {key: resolve_path(getattr(self, key), base_dir) for key in self.PATHS}
        if isinstance(self, GroundTruthOptions):
            update |= self.resolved_paths(base_dir)
        return self.model_copy(update=update)

    def ground_truth(self) -> GroundTruthOptions:
        """This source's ground-truth options (the fields it shares with GroundTruthOptions)."""
        keys = set(GroundTruthOptions.model_fields)
        return GroundTruthOptions.model_validate(
            {k: v for k, v in self.model_dump().items() if k in keys})


class _Recording(_Entry):
    """A recording with its own sensor name and intensities."""

    sensor: str = "unknown"
    intensity: IntensityMode = "auto"


class RosbagEntry(_Recording, GroundTruthOptions):
    """A ROS 1 .bag file or ROS 2 bag folder (``adaptune ingest rosbag``)."""

    kind: Literal["rosbag"]
    topic: str | None = None

    def open(self) -> list[Source]:
        from pipeline.sources.rosbag import RosbagSource

        return [RosbagSource(self.path, self.topic, self.ground_truth(), self.name, self.sensor)]


class McapEntry(_Recording, GroundTruthOptions):
    """Any MCAP with PointCloud2 messages (``adaptune ingest mcap``)."""

    kind: Literal["mcap"]
    topic: str | None = None

    def open(self) -> list[Source]:
        from pipeline.sources.mcap_file import McapSource

        return [McapSource(self.path, self.topic, self.ground_truth(), self.name, self.sensor)]


class FolderEntry(_Recording, GroundTruthOptions):
    """A folder of scan files, one a frame, and a pose file (``adaptune ingest folder``)."""

    kind: Literal["folder"]
    times: str | None = None
    rate_hz: float = Field(10.0, gt=0)

    PATHS: ClassVar[tuple[str, ...]] = ("path", "times")

    @model_validator(mode="after")
    def _no_topic(self) -> FolderEntry:
        if self.gt_topic is not None:
            raise ValueError(f"a scan folder has no topics: give its ground truth as poses, got "
                             f"(gt_topic={self.gt_topic!r})")
        return self

    def open(self) -> list[Source]:
        from pipeline.sources.folder import FolderSource

        return [FolderSource(self.path, self.ground_truth(), self.times, self.rate_hz,
                             self.name, self.sensor)]


class KittiEntry(_Entry):
    """Sequences of a KITTI odometry root (``adaptune ingest kitti``), one MCAP each."""

    kind: Literal["kitti"]
    sequences: list[str] = Field(min_length=1)
    start: int | None = Field(None, ge=0)
    end: int | None = Field(None, ge=0)

    @field_validator("sequences")
    @classmethod
    def _plain(cls, sequences: list[str]) -> list[str]:
        for seq in sequences:  # each names ROOT/sequences/<seq> and the MCAP <seq>.mcap
            check_plain_name(seq, "a KITTI sequence", ValueError)
        return sequences

    @model_validator(mode="after")
    def _consistent(self) -> KittiEntry:
        if self.start is not None and self.end is not None and self.end < self.start:
            raise ValueError(f"end must be >= start, got (start={self.start}, end={self.end})")
        if self.name is not None and len(self.sequences) != 1:
            raise ValueError(f"a name needs exactly one sequence, got (name={self.name!r}, "
                             f"sequences={self.sequences})")
        return self

    def open(self) -> list[Source]:
        from pipeline.sources.kitti import KittiSource

        return [KittiSource(self.path, seq, self.start, self.end, self.name)
                for seq in self.sequences]


SourceEntry = Annotated[RosbagEntry | McapEntry | FolderEntry | KittiEntry,
                        Field(discriminator="kind")]


class DataSection(Section):
    """params.yaml ``data``: recordings of your own and their splits (module docstring)."""

    sources: list[SourceEntry] = Field(default_factory=list)

    @field_validator("sources")
    @classmethod
    def _has_training(cls, sources: list[Any]) -> list[Any]:
        if sources and not any(s.split == "train" for s in sources):
            raise ValueError(f"no recording in split 'train' (the one tuned on), got splits "
                             f"{sorted({s.split for s in sources})}")
        return sources

    def resolved(self, base_dir: str | Path) -> DataSection:
        """A copy with every path absolute, relative ones from ``base_dir`` (the folder of
        the params file)."""
        base = Path(base_dir).expanduser().resolve()
        return self.model_copy(update={"sources": [s.resolved(base) for s in self.sources]})


def check_length(source: Source, length_m: float, what: str) -> bool:
    """InputError, naming ``what``, when ``source``'s ground truth runs no longer than
    ``length_m`` (base.length_m: an RTE segment of that length must fit, as the trials and the
    evaluation require: ``pipeline.metrics.rte.check_scorable``); False when it has no ground
    truth, True when it is long enough."""
    from pipeline.metrics.rte import check_scorable

    gt = source.ground_truth_poses()
    if gt is None:
        return False
    try:
        check_scorable(gt, length_m, what)
    except InputError as exc:
        raise InputError(f"{exc} (base.length_m, the RTE's length, `adaptune init --length`: "
                         "give a longer recording or a smaller length)") from None
    return True


def ingest_data_set(section: DataSection, out_dir: str | Path, base_dir: str | Path,
                    length_m: float | None = None) -> list[IngestReport]:
    """Ingest every recording of ``section`` into ``out_dir`` (module docstring); relative
    paths are relative to ``base_dir``. ConfigError when two recordings have one name;
    InputError, before any is written, when a recording's ground truth runs no longer than
    ``length_m`` (``check_length``)."""
    out_dir = Path(out_dir)
    if not section.sources:
        log.info("ingest: no data sources configured, writing an empty data set")
    opened = [(entry, source) for entry in section.resolved(base_dir).sources
              for source in entry.open()]
    splits: dict[str, list[str]] = {"train": [], "validation": []}
    where: dict[str, str] = {}
    for entry, source in opened:
        name = source.sequence_info().name
        check_plain_name(name, f"data.sources: the name of {entry.path}")
        if name in where:
            raise ConfigError(f"data.sources: two recordings are named {name!r} ({where[name]}, "
                              f"{entry.path}); give one of them a name")
        where[name] = entry.path
        splits.setdefault(entry.split, []).append(name)
        if length_m is not None:
            check_length(source, length_m, f"data.sources: {entry.path} (sequence {name})")
    output_folder(out_dir)  # once every recording opened and every name is checked
    reports = []
    for i, (entry, source) in enumerate(opened, 1):
        name = source.sequence_info().name
        log.info("ingest [%d/%d] %s: %s", i, len(opened), name, entry.path)
        intensity: IntensityMode = entry.intensity if isinstance(entry, _Recording) else "auto"
        reports.append(write_sequence(source, out_dir / f"{name}.mcap", intensity))
    write_index(out_dir, {s: splits[s] for s in SPLITS if s in splits})
    return reports
