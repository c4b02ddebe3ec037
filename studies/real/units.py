"""The units of the real-data study: every run cut into its two halves by distance.

The runs are the sequences the ingest stage wrote (a run cut into pieces where its keyframes
leave a gap is several: ``<run>_p<k>``, in order). A run's path length is that of its pieces
together; its first half is every frame up to half of it, the second the rest, so a piece that
straddles the half is cut in two there. Every stretch becomes a unit MCAP, ``<piece>_h1`` or
``<piece>_h2``, with the run's metadata (its sensor, its own L) and where its frames came from
(``x.run``, ``x.half``, ``x.first_frame``: the piece's frame the unit starts at). A stretch whose
ground truth is not longer than its L is dropped (no sub-trajectory to score) and said so in the
units' record. ``units.json`` lists the units: name, run, half, frames, path length and the
most a run that finishes can score on it (``finishing_bound_pct``), which the study's penalty
must exceed (a failed run must never score better than one that finishes).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from studies.real.folds import Unit

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UnitRecord:
    """A unit as ``units.json`` lists it."""

    name: str
    run: str
    half: str
    piece: str
    first_frame: int
    frames: int
    start_m: float
    path_m: float
    finishing_bound_pct: float

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def make_units(runs_dir: Path, runs: Sequence[str], penalty_pct: float,
               out: Path) -> list[UnitRecord]:
    """Cut every run of ``runs`` (its pieces in ``runs_dir``) into its halves (module
    docstring), write the units into ``out`` (MCAPs, index.json: every unit in ``train``,
    units.json) atomically and return them. ConfigError, naming the unit, when a run that
    finishes could score ``penalty_pct`` [%] or more on one."""
    from pipeline.io_utils import atomic_dir
    from pipeline.sequence_index import write_index

    with atomic_dir(out) as tmp:
        units: list[UnitRecord] = []
        dropped: list[str] = []
        for run in runs:
            kept, lost = cut_run(run, run_pieces(runs_dir, run), tmp)
            units += kept
            dropped += lost
        check_penalty(units, penalty_pct)
        (tmp / "units.json").write_text(json.dumps(
            {"units": [u.to_json() for u in units], "dropped": dropped}, indent=2) + "\n")
        write_index(tmp, {"train": [u.name for u in units]})
    return units


def run_pieces(runs_dir: Path, run: str) -> list[Path]:
    """The run's sequence MCAPs in order: ``<run>.mcap``, or its pieces ``<run>_p<k>.mcap``."""
    whole = runs_dir / f"{run}.mcap"
    if whole.is_file():
        return [whole]
    pieces = sorted(runs_dir.glob(f"{run}_p*.mcap"),
                    key=lambda p: int(p.stem.rsplit("_p", 1)[1]))
    if not pieces:
        from pipeline.errors import InputError

        raise InputError(f"{runs_dir}: no sequence of run {run!r} ({run}.mcap or its pieces)")
    return pieces


def cut_run(run: str, pieces: Sequence[Path], out: Path) -> tuple[list[UnitRecord], list[str]]:
    """The run's units written into ``out`` and the lines of the stretches dropped."""
    from pipeline.geometry import path_distances
    from pipeline.sequence import read_ground_truth

    gts = [read_ground_truth(p, "to cut the run into halves") for p in pieces]
    lengths = [float(path_distances(g)[-1]) if len(g) else 0.0 for g in gts]
    half_m = sum(lengths) / 2
    kept: list[UnitRecord] = []
    dropped: list[str] = []
    before = 0.0
    for piece, gt, length in zip(pieces, gts, lengths, strict=True):
        d = before + path_distances(gt)
        cut = int(np.searchsorted(d, half_m, side="right"))  # first frame past the half
        for half, (a, b) in (("h1", (0, cut)), ("h2", (cut, len(gt)))):
            if b - a < 2:
                continue
            record, why = write_unit(piece, f"{piece.stem}_{half}", run, half, a, b,
                                     float(d[a]), out)
            if record is None:
                dropped.append(why)
            else:
                kept.append(record)
        before += length
    return kept, dropped


def write_unit(piece: Path, name: str, run: str, half: str, start: int, stop: int,
               start_m: float, out: Path) -> tuple[UnitRecord | None, str]:
    """Frames ``start``..``stop - 1`` of ``piece`` as the unit ``name``, ``start_m`` [m] along
    the run's reference (its pieces' paths joined) from the run's start (None and the reason
    when its ground truth is not longer than its L)."""
    from dataclasses import replace

    from pipeline.geometry import path_distances
    from pipeline.sequence import SequenceReader, SequenceWriter

    with SequenceReader(piece) as reader:
        info = reader.info
        scans = [reader[i] for i in range(start, stop)]
    gt = np.stack([s.T_world_lidar for s in scans])  # type: ignore[misc]
    path_m = float(path_distances(gt)[-1])
    length_m = info.length_m
    if length_m is None or info.jump_limit_m is None:
        from pipeline.errors import InputError

        raise InputError(f"{piece}: no RTE length or jump limit of its own (the real runs' "
                         "sources set length_m and jump_limit_m)")
    if path_m <= length_m:
        return None, (f"{name} ({piece.stem} frames {start}-{stop - 1}): ground truth runs "
                      f"{path_m:.1f} m, not longer than its L = {length_m:g} m")
    extra = {**info.extra, "run": run, "half": half, "piece": piece.stem,
             "first_frame": str(start)}
    unit_info = replace(info, name=name, labels=[], frame_count=stop - start, extra=extra)
    with SequenceWriter(out / f"{name}.mcap", unit_info) as writer:
        for scan in scans:
            writer.add(scan.stamp_ns, scan.points_lidar, scan.T_world_lidar, scan.time_s)
    bound = finishing_bound_pct(gt, length_m, info.jump_limit_m)
    return UnitRecord(name, run, half, piece.stem, start, stop - start, start_m, path_m,
                      bound), ""


def finishing_bound_pct(gt: NDArray[np.float64], length_m: float, jump_limit_m: float) -> float:
    """The most RTE [%] a run that finishes can score on a sequence of ground truth ``gt``
    (N, 4, 4) at L = ``length_m``, every step of it within ``jump_limit_m`` (a longer one fails
    the run): over a sub-trajectory from frame i to its end j, the error's translation is at
    most the reference's displacement (at most L plus its last step) plus the estimate's (at
    most (j - i) jump limits), so 100 (L + the largest step + S J) / L, S the most frames one
    sub-trajectory spans."""
    from pipeline.geometry import path_distances
    from pipeline.metrics.rte import segment_ends

    steps_m = np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1)
    ends = segment_ends(path_distances(gt), length_m)
    starts = np.flatnonzero(ends >= 0)
    spans = int((ends[starts] - starts).max()) if len(starts) else 0
    largest = float(steps_m.max()) if len(steps_m) else 0.0
    return 100.0 * (length_m + largest + spans * jump_limit_m) / length_m


def check_penalty(units: Sequence[UnitRecord], penalty_pct: float) -> None:
    """ConfigError unless ``penalty_pct`` exceeds every unit's finishing bound."""
    over = [u for u in units if u.finishing_bound_pct >= penalty_pct]
    if over:
        from pipeline.errors import ConfigError

        worst = max(over, key=lambda u: u.finishing_bound_pct)
        raise ConfigError(f"trials.penalty_pct must exceed what a run that finishes can score, "
                          f"got {penalty_pct:g} % <= {worst.finishing_bound_pct:.0f} % on unit "
                          f"{worst.name} (its L, jump limit and steps: "
                          "studies.real.units.finishing_bound_pct)")


def read_unit_records(units_dir: Path) -> list[UnitRecord]:
    """The units ``make_units`` wrote, as ``units.json`` lists them."""
    data = json.loads((units_dir / "units.json").read_text(encoding="utf-8"))
    return [UnitRecord(**u) for u in data["units"]]


def read_units(units_dir: Path) -> list[Unit]:
    """The units ``make_units`` wrote (their name, run and half)."""
    return [Unit(u.name, u.run, u.half) for u in read_unit_records(units_dir)]
