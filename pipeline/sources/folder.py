"""A folder of scan files (.bin / .pcd / .ply), one a frame, with an optional pose file.

Order: by the numbers in the file names (pipeline.sources.ordering; ambiguous names are
refused). Stamps, the first that applies: a times file (seconds, one a line, as KITTI's
times.txt); file names that are stamps; a stamped pose file (TUM, EuRoC, a 4x4 block with
stamps), one pose per scan in order; else frame k is at k / rate_hz seconds. Scans named by
frame number (``000123.pcd``) take row 123 of a times file or of a pose file without stamps
that is longer than the folder (a slice of a KITTI sequence needs no hand-cut files; numbers
count from 0, as KITTI's: a warning says which lines were used); otherwise row k is scan k.
The lines used are in the sequence's metadata (``pose_lines``, ``times_lines``; ``info``).
Ground truth (``pipeline.sources.poses.GroundTruthOptions``, no topic): a pose file of any
format pipeline.posefile reads; with stamps it is
matched by time when the scans' stamps come from elsewhere, without stamps pose k is scan k.
``extrinsic`` (E = T_x_lidar, e.g. KITTI's Tr) turns poses of another frame into LiDAR poses;
without it a ground truth that moves along the sensor's z axis gets a warning.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.posefile import PoseFile
from pipeline.sequence import SequenceInfo
from pipeline.sources.base import (
    Frame,
    IngestReport,
    IntensityMode,
    input_files,
    write_sequence,
)
from pipeline.sources.ordering import (
    frame_numbers,
    lines_used,
    name_stamps_ns,
    natural_order,
    rows_for_scans,
)
from pipeline.sources.pointtime import relative_times_s
from pipeline.sources.poses import GroundTruthOptions, check_count, lidar_ground_truth
from pipeline.sources.scanfiles import SCAN_SUFFIXES, read_scan, scan_files
from pipeline.stamps import read_times, seconds_to_ns


class FolderSource:
    """Scans of a folder, one file a frame, in the natural order of their names."""

    name: ClassVar[str] = "folder"

    def __init__(
        self,
        folder: str | Path,
        gt: GroundTruthOptions | None = None,
        times: str | Path | None = None,
        rate_hz: float = 10.0,
        name: str | None = None,
        sensor: str = "unknown",
    ) -> None:
        gt = gt or GroundTruthOptions()
        if gt.gt_topic is not None:
            raise ConfigError(f"{folder}: a scan folder has no topics, got gt_topic="
                              f"{gt.gt_topic!r}; give its ground truth as a pose file (poses)")
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise InputError(f"{self.folder}: no such folder")
        files = scan_files(self.folder, SCAN_SUFFIXES)
        kinds = {p.suffix.lower() for p in files}
        if len(kinds) > 1:
            raise InputError(f"{self.folder}: mixed scan file types {sorted(kinds)}; keep one kind")
        self.files = natural_order(files, str(self.folder))
        self.numbers = frame_numbers(self.files)
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"--rate must be a finite number > 0 Hz, got {rate_hz}")
        self.seq_name = name or self.folder.name
        self.sensor = sensor
        self.lines: dict[str, str] = {}  # which lines of the pose / times file (metadata)
        pf = gt.pose_file()
        if pf is not None and pf.stamps_ns is None:  # one pose a frame: the scans' rows
            rows = rows_for_scans(len(pf.T_world_x), len(self.files), self.numbers,
                                  str(pf.path), "poses")
            self.lines["pose_lines"] = lines_used(rows, len(pf.T_world_x))
            pf = replace(pf, T_world_x=pf.T_world_x[rows])
        self.stamps_ns, self.stamps_from = self._stamps(pf, times, rate_hz)
        truth = lidar_ground_truth(None, pf, gt.extrinsic, len(self.files), str(self.folder))
        self.T_world_lidar = None if truth is None else truth.all_at(self.stamps_ns)
        self.gt_note = "none" if pf is None else f"pose file {gt.poses}"
        self.inputs = input_files(*self.files, times, *gt.files())

    def _stamps(self, pf: PoseFile | None, times: str | Path | None,
                rate_hz: float) -> tuple[NDArray[np.int64], str]:
        n = len(self.files)
        if times is not None:
            every = read_times(Path(times), None)
            rows = rows_for_scans(len(every), n, self.numbers, str(times), "stamps")
            self.lines["times_lines"] = lines_used(rows, len(every))
            return every[rows], f"times file {Path(times).name}"
        from_names = name_stamps_ns(self.files)
        if from_names is not None:
            if np.any(np.diff(from_names) <= 0):
                raise InputError(f"{self.folder}: two scan files have the same stamp name")
            return from_names, "file names"
        if pf is not None and pf.stamps_ns is not None:
            check_count(pf, n, str(self.folder))
            return pf.stamps_ns, f"pose file {pf.path.name}"
        with np.errstate(over="ignore"):  # a rate near 0: infinite, refused just below
            t_s = np.arange(n) / rate_hz
        return seconds_to_ns(t_s, f"--rate {rate_hz:g} Hz"), f"{rate_hz:g} Hz"

    def sequence_info(self) -> SequenceInfo:
        return SequenceInfo(name=self.seq_name, sensor=self.sensor,
                            source=f"folder:{self.folder.resolve()}",
                            extra={"stamps": self.stamps_from, "order": "natural (file names)",
                                   "ground_truth": self.gt_note, **self.lines})

    def expected_frames(self) -> int:
        return len(self.files)

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        return None if self.T_world_lidar is None else self.T_world_lidar.copy()

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        return self.stamps_ns.copy()

    def frames(self) -> Iterator[Frame]:
        for k, path in enumerate(self.files):
            scan = read_scan(path)
            stamp = int(self.stamps_ns[k])
            times = (None if scan.time is None or scan.time_field is None
                     else relative_times_s(scan.time, scan.time_field, stamp, str(path)))
            yield Frame(stamp, scan.points,
                        None if self.T_world_lidar is None else self.T_world_lidar[k],
                        str(path), times)


def ingest_folder(
    folder: str | Path,
    out: str | Path,
    gt: GroundTruthOptions | None = None,
    times: str | Path | None = None,
    rate_hz: float = 10.0,
    name: str | None = None,
    sensor: str = "unknown",
    intensity: IntensityMode = "auto",
) -> IngestReport:
    """Scan files of ``folder`` (natural name order) + optional pose file -> MCAP ``out``."""
    return write_sequence(FolderSource(folder, gt, times, rate_hz, name, sensor), out, intensity)
