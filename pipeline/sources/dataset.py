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

Every kind also takes ``length_m``, the RTE length L [m] its sequences are scored at, recorded
in each (``SequenceInfo.length_m``) and winning over ``base.length_m`` in every stage that
scores them (docs/design.md, "Stages"), ``jump_limit_m``, likewise recorded
(``SequenceInfo.jump_limit_m``) and winning over ``trials.jump_limit_m`` when a trial's
trajectory is checked for jumps (a drive whose keyframes are 6 m apart needs more than 5 m),
and ``pieces`` (``pipeline.sources.pieces``): its run
cut where a time step or a reference step exceeds a limit, each piece a sequence
``<name>_p<k>`` of its own, the pieces no longer than L dropped.

Relative paths (path, poses, times, an extrinsic file) are relative to the folder of the params
file, not the working directory, and ``~`` is the home folder. ``ingest_data_set`` checks
every recording first (layout, topics, ground truth, unique names, and that its ground truth
runs longer than its L, its own or base.length_m: ``check_length``; with pieces, that one
piece does), then writes ``<out>/<name>.mcap`` for each sequence and ``<out>/index.json``
({"train": [...], "validation": [...], "test": [...]}; test only when a recording is in it),
the layout the ``simulate`` stage writes, so every later stage reads either. With no sources
it writes an empty index. What each source became (its sequences, frames, path lengths, L, the
pieces dropped) is the stage's record (``IngestedSet.record``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator, model_validator

from pipeline.config import Section
from pipeline.errors import ConfigError, InputError
from pipeline.geometry import path_distances
from pipeline.io_utils import check_plain_name, output_folder
from pipeline.sequence_index import write_index
from pipeline.sources.base import IngestReport, IntensityMode, Source, write_sequence
from pipeline.sources.pieces import PieceSource, PiecesSection, RunFrames, cut_run, keep_pieces
from pipeline.sources.poses import GroundTruthOptions, resolve_path

log = logging.getLogger(__name__)

Split = Literal["train", "validation", "test"]
SPLITS: tuple[str, ...] = ("train", "validation", "test")
NAME_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$"
"""A sequence name is the stem of its MCAP file: letters, digits, ``_``, ``.``, ``-``."""


class _Entry(Section):
    """What every source of ``data.sources`` has: its input, its split, its name, its own RTE
    length (None: base.length_m), its own jump limit (None: trials.jump_limit_m) and where its
    run is cut into pieces (None: nowhere)."""

    path: str = Field(min_length=1)
    split: Split = "train"
    name: str | None = Field(None, pattern=NAME_PATTERN)
    length_m: float | None = Field(None, gt=0)
    jump_limit_m: float | None = Field(None, gt=0)
    pieces: PiecesSection | None = None

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


def check_length(gt: NDArray[np.float64], length_m: float, what: str, own: bool) -> None:
    """InputError, naming ``what``, when the ground truth ``gt`` (N, 4, 4) runs no longer than
    ``length_m`` (an RTE segment of that length must fit, as the trials and the evaluation
    require: ``pipeline.metrics.rte.check_scorable``): the recording's own length_m
    (``own``) or base.length_m, which the message names."""
    from pipeline.metrics.rte import check_scorable

    try:
        check_scorable(gt, length_m, what)
    except InputError as exc:
        setting = ("the recording's own length_m" if own else
                   "base.length_m, the RTE's length, `adaptune init --length`")
        raise InputError(f"{exc} ({setting}: give a longer recording or a smaller length)"
                         ) from None


@dataclass
class IngestedSet:
    """What ``ingest_data_set`` wrote: a report per sequence, and ``record``: per source, the
    sequences it became (name, frames, the run's frames it holds, the length of its ground
    truth [m]) at its RTE length, and one line per piece dropped (the ingest stage's record,
    ``records/ingest.json``)."""

    reports: list[IngestReport] = field(default_factory=list)
    record: dict[str, Any] = field(default_factory=lambda: {"sources": []})

    @property
    def dropped(self) -> list[str]:
        """The record's lines of the pieces dropped, every source's."""
        return [line for s in self.record["sources"] for line in s["dropped"]]


@dataclass
class SourcePlan:
    """What one opened source writes: its sequences (name, source) and its entry of the
    ingest record; ``run``: the one pass its pieces share (None without pieces);
    ``has_ground_truth``: whether it has any."""

    entry: Any
    sequences: list[tuple[str, Source]]
    record: dict[str, Any]
    has_ground_truth: bool
    run: RunFrames | None = None


def plan_source(entry: Any, source: Source, length_m: float | None, what: str) -> SourcePlan:
    """The sequences ``source`` (opened from ``entry``, a ``data`` source) becomes, checked
    (``what`` names it in errors) at its RTE length, the entry's own or else ``length_m``
    (None: no check): its ground truth must run longer (``check_length``); with pieces, the
    pieces whose ground truth does not are dropped, one line each in the record, and
    InputError when none is left (``pipeline.sources.pieces.keep_pieces``)."""
    name = source.sequence_info().name
    own = entry.length_m is not None
    scored_m = entry.length_m if own else length_m
    record: dict[str, Any] = {"path": entry.path, "kind": entry.kind, "split": entry.split,
                              "length_m": scored_m, "sequences": [], "dropped": []}
    if entry.jump_limit_m is not None:  # no key without one: the records stay as they were
        record["jump_limit_m"] = entry.jump_limit_m
    gt = source.ground_truth_poses()
    if entry.pieces is None:
        if scored_m is not None and gt is not None:
            check_length(gt, scored_m, what, own)
        n = len(gt) if gt is not None else source.expected_frames()
        record["sequences"].append(
            {"name": name, "frames": n, "run_frames": None if n is None else f"0-{n - 1} of {n}",
             "path_m": None if gt is None else float(path_distances(gt)[-1])})
        return SourcePlan(entry, [(name, source)], record, gt is not None)
    pieces = cut_run(source.frame_stamps_ns(), gt, entry.pieces, what)
    kept = keep_pieces(pieces, scored_m, what)
    run = RunFrames(source)
    sequences: list[tuple[str, Source]] = []
    for piece in pieces:
        if piece not in kept:
            record["dropped"].append(piece.dropped_line(name, scored_m))  # type: ignore[arg-type]
            continue
        sequences.append((piece.name(name), PieceSource(run, piece)))
        record["sequences"].append({"name": piece.name(name), "frames": piece.frames,
                                    "run_frames": piece.span(), "path_m": piece.path_m})
    return SourcePlan(entry, sequences, record, gt is not None, run)


def ingest_data_set(section: DataSection, out_dir: str | Path, base_dir: str | Path,
                    length_m: float | None = None) -> IngestedSet:
    """Ingest every recording of ``section`` into ``out_dir`` (module docstring); relative
    paths are relative to ``base_dir``; ``length_m``: base.length_m, the RTE length of the
    recordings without one of their own (None: no length check, no piece dropped).
    ConfigError when two sequences have one name; InputError, before any is written, when a
    recording's ground truth runs no longer than its RTE length (``check_length``), or with
    pieces when no piece's does (``pipeline.sources.pieces.keep_pieces``)."""
    out_dir = Path(out_dir)
    if not section.sources:
        log.info("ingest: no data sources configured, writing an empty data set")
    resolved = section.resolved(base_dir).sources
    where: dict[str, str] = {}
    plans = []
    for given, entry in zip(section.sources, resolved, strict=True):
        for source in entry.open():
            name = source.sequence_info().name
            check_plain_name(name, f"data.sources: the name of {entry.path}")
            plan = plan_source(entry, source, length_m,
                               f"data.sources: {entry.path} (sequence {name})")
            for seq, _ in plan.sequences:
                if seq in where:
                    raise ConfigError(f"data.sources: two recordings are named {seq!r} "
                                      f"({where[seq]}, {entry.path}); give one of them a name")
                where[seq] = entry.path
            plan.record["path"] = given.path  # as params.yaml gives it (the record is in git)
            plans.append(plan)
    output_folder(out_dir)  # once every recording opened and every name is checked
    done = IngestedSet()
    splits: dict[str, list[str]] = {"train": [], "validation": []}
    count = sum(len(plan.sequences) for plan in plans)
    for plan in plans:
        intensity: IntensityMode = (plan.entry.intensity if isinstance(plan.entry, _Recording)
                                    else "auto")
        try:
            for name, source in plan.sequences:
                log.info("ingest [%d/%d] %s: %s", len(done.reports) + 1, count, name,
                         plan.entry.path)
                done.reports.append(write_sequence(source, out_dir / f"{name}.mcap", intensity,
                                                   plan.entry.length_m, plan.entry.jump_limit_m))
                splits.setdefault(plan.entry.split, []).append(name)
        finally:
            if plan.run is not None:
                plan.run.close()
        done.record["sources"].append(plan.record)
    write_index(out_dir, {s: splits[s] for s in SPLITS if s in splits})
    return done
