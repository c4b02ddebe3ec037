"""What every ingest source is: a Protocol, the Frame it yields, and the one writer loop.

A source is opened on its input (a KITTI sequence, a bag, a folder, an MCAP) with its options,
checks what it can up front (layout, counts, pose files), then yields ``Frame``s in time order.
``write_sequence`` streams them into a sequence MCAP (pipeline.sequence.SequenceWriter):
non-finite points are dropped and counted, a scan with no finite point is an error naming the
input file, and any error leaves no output file behind (the writer is atomic).
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import InputError
from pipeline.io_utils import refuse_input_as_output
from pipeline.progress import progress
from pipeline.sequence import SequenceInfo, SequenceWriter

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    """One scan as a source reads it.

    stamp_ns: sensor time [ns]; points_lidar: (N, 3) or (N, 4) float32 x, y, z [m] (+ intensity)
    in the sensor frame, possibly with non-finite rows; T_world_lidar: (4, 4) ground truth or
    None; what: where it came from, for error messages (a file, or ``bag topic #k``);
    time_s: (N,) per-point time [s] relative to ``stamp_ns`` (pipeline.sources.pointtime), or
    None.
    """

    stamp_ns: int
    points_lidar: NDArray[np.float32]
    T_world_lidar: NDArray[np.float64] | None
    what: str
    time_s: NDArray[np.float32] | None = None


@runtime_checkable
class Source(Protocol):
    """An ingest source. ``name`` is its registry key (``adaptune ingest <name>``)."""

    name: ClassVar[str]
    inputs: tuple[Path, ...]
    """Every file it reads (scans, pose, times and calibration files): never the output."""

    def sequence_info(self) -> SequenceInfo:
        """Name, sensor and source description of the sequence it produces."""
        ...

    def expected_frames(self) -> int | None:
        """Number of frames it will yield, when known before reading them."""
        ...

    def frames(self) -> Iterator[Frame]:
        """The scans in time order."""
        ...

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        """(N, 4, 4) T_world_lidar of the N scans ``frames`` yields (their ``T_world_lidar``),
        None without ground truth; without decoding the scans' points, so that what needs
        the ground truth (its length: ``pipeline.sources.dataset.check_length``) is checked
        before anything is written."""
        ...

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        """(N,) the stamps [ns] of the N scans ``frames`` yields (their ``stamp_ns``), without
        decoding the scans' points: where a run is cut into pieces
        (``pipeline.sources.pieces``) is decided before anything is written."""
        ...


def input_files(*items: str | Path | None) -> tuple[Path, ...]:
    """The items that name existing files or folders (an ``--extrinsic`` may be numbers)."""
    found = []
    for item in items:
        try:
            if item is not None and Path(item).exists():
                found.append(Path(item))
        except OSError:  # numbers too long for a file name
            continue
    return tuple(found)


@dataclass(frozen=True)
class IngestReport:
    """What an ingest wrote: ``frames`` scans with ``points`` points in total, after
    dropping ``dropped_points`` non-finite ones, into ``out`` in ``seconds``;
    ``ground_truth_from``: where the ground truth came from (a topic, a pose file), or ""."""

    out: Path
    frames: int
    points: int
    dropped_points: int
    has_ground_truth: bool
    seconds: float
    ground_truth_from: str = ""


IntensityMode = Literal["auto", "keep"]


def intensity_scale(first_points: NDArray[np.float32], what: str) -> tuple[float, str]:
    """(factor, what was done) for the intensities of a sequence, from its first scan.

    KITTI reflectance is 0-1; many drivers and PCD files give 0-255 (8 bit) or 0-65535
    (16 bit). Those are scaled to 0-1, so every sequence has one intensity range.
    """
    finite = first_points[:, 3][np.isfinite(first_points[:, 3])]
    top = float(finite.max()) if finite.size else 0.0
    if finite.size and finite.min() < 0:
        return 1.0, "kept as recorded (negative values: not a 0-1, 0-255 or 0-65535 range)"
    if top <= 1.0:
        return 1.0, "0-1 as recorded"
    if top <= 255.0:
        return 1 / 255, "0-255 scaled to 0-1 (x 1/255)"
    if top <= 65535.0:
        return 1 / 65535, "0-65535 scaled to 0-1 (x 1/65535)"
    log.warning("%s: intensities up to %.3g, not a known range: kept as recorded", what, top)
    return 1.0, f"kept as recorded (up to {top:.3g}, not a known range)"


def write_sequence(source: Source, out: str | Path, intensity: IntensityMode = "auto",
                   length_m: float | None = None,
                   jump_limit_m: float | None = None) -> IngestReport:
    """Stream every frame of ``source`` into the sequence MCAP ``out`` (atomically).

    ``intensity``: "auto" scales 0-255 or 0-65535 intensities to 0-1 (``intensity_scale``,
    decided on the first scan), "keep" writes them as recorded; the metadata says which
    (``x.intensity``), and whether the scans carry per-point time (``x.point_time``).
    ``length_m``: the RTE length the sequence is scored at (``SequenceInfo.length_m``; None:
    none of its own, the stages' base.length_m); ``jump_limit_m``: the trials' jump limit on
    it (``SequenceInfo.jump_limit_m``; None: trials.jump_limit_m).
    """
    t0 = time.perf_counter()
    out = Path(out)
    refuse_input_as_output(out, source.inputs)
    frames_iter = iter(source.frames())
    first = next(frames_iter, None)
    if first is None:
        raise InputError(f"{source.sequence_info().name}: no frames to write")
    info = source.sequence_info()
    if length_m is not None:
        info.length_m = length_m
    if jump_limit_m is not None:
        info.jump_limit_m = jump_limit_m
    scale, note = (intensity_scale(_as_points(first), first.what) if intensity == "auto"
                   else (1.0, "kept as recorded (--intensity keep)"))
    info.extra["intensity"] = note
    info.extra["point_time"] = ("per-point time [s] in the PointCloud2 field 'time'"
                                if first.time_s is not None else "none")
    points = dropped = 0
    with_gt: bool | None = None
    with SequenceWriter(out, info) as writer:
        for frame in progress(itertools.chain([first], frames_iter), source.expected_frames(),
                              f"ingest {info.name}", "scan"):
            pts = _as_points(frame)
            has_gt = frame.T_world_lidar is not None
            if with_gt is None:
                with_gt = has_gt
            elif has_gt != with_gt:
                raise InputError(
                    f"{frame.what}: has {'a' if has_gt else 'no'} ground-truth pose "
                    f"unlike the frames before it"
                )
            if (frame.time_s is None) != (first.time_s is None):
                raise InputError(f"{frame.what}: has {'no ' if frame.time_s is None else ''}"
                                 "per-point time unlike the frames before it")
            if scale != 1.0 and pts.shape[1] == 4:
                pts = pts.copy()
                pts[:, 3] = np.minimum(pts[:, 3] * np.float32(scale), np.float32(1.0))
            before = writer.dropped_points
            try:  # the writer drops and counts non-finite points, refuses an empty scan
                writer.add(frame.stamp_ns, pts, frame.T_world_lidar, frame.time_s)
            except InputError as exc:
                raise InputError(f"{frame.what}: {exc}") from None
            n_bad = writer.dropped_points - before
            if n_bad:
                log.info("%s: dropped %d non-finite points", frame.what, n_bad)
            points += len(pts) - n_bad
            dropped += n_bad
        frames = len(writer.stamps_ns)
    if dropped:
        log.warning("%s: dropped %d non-finite points in total", out, dropped)
    return IngestReport(out, frames, points, dropped, bool(with_gt), time.perf_counter() - t0,
                        info.extra.get("ground_truth", "") if with_gt else "")


def _as_points(frame: Frame) -> NDArray[np.float32]:
    pts = np.asarray(frame.points_lidar, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] not in (3, 4):
        raise InputError(f"{frame.what}: points must be (N, 3) or (N, 4), got shape {pts.shape}")
    if len(pts) == 0:
        raise InputError(f"{frame.what}: empty scan (0 points)")
    return pts
