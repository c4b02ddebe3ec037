"""A run cut into contiguous pieces where it has a gap: a ``data`` source's ``pieces`` option.

``PiecesSection`` (``max_time_step_s``, ``max_step_m``; either or both) cuts a run between
frames j and j + 1 where the time step stamp[j + 1] - stamp[j] exceeds ``max_time_step_s`` or
the reference step |p[j + 1] - p[j]| (the distance between consecutive ground-truth positions)
exceeds ``max_step_m``: keyframes missing there leave a gap no scan-to-scan odometry bridges.
The pieces are numbered k = 0, 1, ... in time order, every piece the cuts make, and piece k
becomes the sequence ``<name>_p<k>``, scored on its own (``cut_run``). A piece whose ground
truth runs no longer than its RTE length is dropped (``Piece.dropped_line`` says so in the
ingest record; the others keep their numbers), and a run of which nothing remains is refused
(``keep_pieces``).

Every piece of a run is read from one pass over the run's source (``RunFrames``): piece k's
frames are the run's next ones, so a bag is decoded once however many pieces it makes. A
piece's metadata names its run and the run's frames it holds (``x.piece_of``,
``x.run_frames``: ``"110-278 of 281"``, 0-based and inclusive, frame j of the piece being
frame 110 + j of the run); its stamps are the run's (``adaptune.frames``).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, model_validator

from pipeline.config import Section
from pipeline.errors import ConfigError, InputError
from pipeline.geometry import path_distances
from pipeline.sequence import SequenceInfo
from pipeline.sources.base import Frame, Source


class PiecesSection(Section):
    """A ``data`` source's ``pieces``: where its run is cut (module docstring). A step equal
    to a limit is no cut; a limit left out (null) cuts nowhere, but one must be given."""

    max_time_step_s: float | None = Field(None, gt=0)
    max_step_m: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _a_limit(self) -> PiecesSection:
        if self.max_time_step_s is None and self.max_step_m is None:
            raise ValueError("pieces needs max_time_step_s or max_step_m (or both; leave "
                             "pieces out for one sequence of the whole run), got neither")
        return self


@dataclass(frozen=True)
class Piece:
    """Frames ``start`` .. ``stop`` - 1 of a run of ``run_frames`` frames, its ``index``-th
    piece; ``path_m``: the length of its ground truth [m] (None without ground truth)."""

    index: int
    start: int
    stop: int
    run_frames: int
    path_m: float | None

    @property
    def frames(self) -> int:
        return self.stop - self.start

    def name(self, run_name: str) -> str:
        """The piece's sequence name: ``<run_name>_p<index>``."""
        return f"{run_name}_p{self.index}"

    def span(self) -> str:
        """The run's frames it holds: ``"110-278 of 281"`` (0-based, inclusive)."""
        return f"{self.start}-{self.stop - 1} of {self.run_frames}"

    def dropped_line(self, run_name: str, length_m: float) -> str:
        """The ingest record's line for this piece, dropped as too short for ``length_m``."""
        return (f"{self.name(run_name)}: frames {self.span()}, {self.path_m:.1f} m of ground "
                f"truth, not longer than its RTE length {length_m:g} m: dropped")


def cut_run(stamps_ns: NDArray[np.int64], T_world_lidar: NDArray[np.float64] | None,
            limits: PiecesSection, what: str) -> list[Piece]:
    """The pieces of a run of N frames (``stamps_ns`` (N,) [ns], ground truth (N, 4, 4) or
    None), cut where a step exceeds ``limits`` (module docstring). ConfigError naming ``what``
    when ``max_step_m`` is given and the run has no ground truth to measure steps on."""
    n = len(stamps_ns)
    cut = np.zeros(max(n - 1, 0), bool)
    if limits.max_time_step_s is not None:
        dt_ns = np.diff(np.asarray(stamps_ns, np.int64)).astype(np.float64)
        cut |= dt_ns > limits.max_time_step_s * 1e9
    if limits.max_step_m is not None:
        if T_world_lidar is None:
            raise ConfigError(f"{what}: pieces.max_step_m cuts at steps of the ground truth, "
                              "and this recording has none (give its poses, or cut by "
                              "max_time_step_s alone)")
        steps = np.linalg.norm(np.diff(T_world_lidar[:, :3, 3], axis=0), axis=1)
        cut |= steps > limits.max_step_m
    bounds = [0, *(int(j) + 1 for j in np.flatnonzero(cut)), n]
    return [Piece(k, a, b, n, None if T_world_lidar is None
                  else float(path_distances(T_world_lidar[a:b])[-1]))
            for k, (a, b) in enumerate(itertools.pairwise(bounds))]


def keep_pieces(pieces: list[Piece], length_m: float | None, what: str) -> list[Piece]:
    """The ``pieces`` whose ground truth runs longer than ``length_m`` (all of them when it is
    None or there is no ground truth); InputError naming ``what`` when none does."""
    kept = [p for p in pieces
            if length_m is None or p.path_m is None or p.path_m > length_m]
    if not kept:
        longest = max(p.path_m or 0.0 for p in pieces)
        raise InputError(f"{what}: no piece's ground truth runs longer than its RTE length "
                         f"{length_m:g} m ({len(pieces)} pieces, the longest {longest:.1f} m): "
                         "nothing to ingest (give wider pieces limits or a smaller length_m)")
    return kept


class RunFrames:
    """The frames of a run's ``source``, read in one pass and handed out piece by piece, in
    order (``take``); ``close`` ends the pass (the source's files close)."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self._frames: Iterator[Frame] | None = None
        self._next = 0  # the run's frame the pass yields next

    def take(self, start: int, stop: int) -> Iterator[Frame]:
        """The run's frames ``start`` .. ``stop`` - 1 (those before ``start`` skipped)."""
        if start < self._next:
            raise ValueError(f"pieces are read in order: frame {start} is behind {self._next}")
        if self._frames is None:
            self._frames = iter(self.source.frames())
        while self._next < stop:
            frame = next(self._frames, None)
            if frame is None:
                raise InputError(f"{self.source.sequence_info().name}: the run ended at frame "
                                 f"{self._next}, before frame {stop - 1}")
            self._next += 1
            if self._next > start:
                yield frame

    def close(self) -> None:
        close = getattr(self._frames, "close", None)
        if close is not None:
            close()


class PieceSource:
    """One piece of a run as a source of its own (a view of a registered source, read
    through the run's ``RunFrames``; not registered itself)."""

    name: ClassVar[str] = "piece"

    def __init__(self, run: RunFrames, piece: Piece) -> None:
        self.run = run
        self.piece = piece
        self.inputs: tuple[Path, ...] = run.source.inputs

    def sequence_info(self) -> SequenceInfo:
        info = self.run.source.sequence_info()
        return replace(info, name=self.piece.name(info.name),
                       extra={**info.extra, "piece_of": info.name,
                              "run_frames": self.piece.span()})

    def expected_frames(self) -> int:
        return self.piece.frames

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        gt = self.run.source.ground_truth_poses()
        return None if gt is None else gt[self.piece.start:self.piece.stop]

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        return self.run.source.frame_stamps_ns()[self.piece.start:self.piece.stop]

    def frames(self) -> Iterator[Frame]:
        return self.run.take(self.piece.start, self.piece.stop)
