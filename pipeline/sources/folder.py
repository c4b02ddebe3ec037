"""A folder of scan files (.bin / .pcd / .ply) in name order, with an optional pose file.

Stamps: a TUM pose file gives them (one pose per scan, line k = scan k); else a times file
(seconds, one a line, as KITTI's times.txt); else frame k is at k / rate_hz seconds.
A KITTI pose file (no stamps) must hold one pose per scan; with ``calib`` (a KITTI calib.txt)
its camera poses become lidar poses (inv(Tr) P Tr), without it they are T_world_lidar as is.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.sequence import SequenceInfo
from pipeline.sources.base import Frame, IngestReport, write_sequence
from pipeline.sources.kitti import read_times
from pipeline.sources.poses import (
    PoseFormat,
    camera_to_lidar,
    check_count,
    read_kitti_calib,
    read_pose_file,
)
from pipeline.sources.scanfiles import SCAN_SUFFIXES, read_scan


class FolderSource:
    """Scans of a folder, one file a frame, sorted by file name."""

    name: ClassVar[str] = "folder"

    def __init__(
        self,
        folder: str | Path,
        poses: str | Path | None = None,
        poses_format: PoseFormat = "auto",
        times: str | Path | None = None,
        calib: str | Path | None = None,
        rate_hz: float = 10.0,
        name: str | None = None,
        sensor: str = "unknown",
    ) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise InputError(f"{self.folder}: no such folder")
        self.files = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in SCAN_SUFFIXES)
        if not self.files:
            raise InputError(f"{self.folder}: no scan files ({', '.join(SCAN_SUFFIXES)})")
        kinds = {p.suffix.lower() for p in self.files}
        if len(kinds) > 1:
            raise InputError(f"{self.folder}: mixed scan file types {sorted(kinds)}; keep one kind")
        if rate_hz <= 0:
            raise ConfigError(f"rate must be > 0 Hz, got {rate_hz}")
        self.seq_name = name or self.folder.name
        self.sensor = sensor
        self.stamps_ns, self.T_world_lidar = self._stamps_and_poses(
            poses, poses_format, times, calib, rate_hz
        )
        self.inputs = tuple(Path(p) for p in (*self.files, poses, times, calib) if p is not None)

    def _stamps_and_poses(
        self,
        poses: str | Path | None,
        fmt: PoseFormat,
        times: str | Path | None,
        calib: str | Path | None,
        rate_hz: float,
    ) -> tuple[NDArray[np.int64], NDArray[np.float64] | None]:
        n = len(self.files)
        pf = read_pose_file(poses, fmt) if poses is not None else None
        if pf is not None:
            check_count(pf, n, str(self.folder))
        if times is not None:
            stamps = read_times(Path(times), n)
        elif pf is not None and pf.stamps_ns is not None:
            stamps = pf.stamps_ns
        else:
            stamps = np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)
        if pf is None:
            return stamps, None
        T = pf.T_world_x
        if calib is not None:
            T = camera_to_lidar(T, read_kitti_calib(calib))
        return stamps, T

    def sequence_info(self) -> SequenceInfo:
        return SequenceInfo(name=self.seq_name, sensor=self.sensor, source=f"folder:{self.folder}")

    def expected_frames(self) -> int:
        return len(self.files)

    def frames(self) -> Iterator[Frame]:
        for k, path in enumerate(self.files):
            yield Frame(
                int(self.stamps_ns[k]),
                read_scan(path),
                None if self.T_world_lidar is None else self.T_world_lidar[k],
                str(path),
            )


def ingest_folder(
    folder: str | Path,
    out: str | Path,
    poses: str | Path | None = None,
    poses_format: PoseFormat = "auto",
    times: str | Path | None = None,
    calib: str | Path | None = None,
    rate_hz: float = 10.0,
    name: str | None = None,
) -> IngestReport:
    """Scan files of ``folder`` (name order) + optional pose file -> sequence MCAP ``out``."""
    return write_sequence(
        FolderSource(folder, poses, poses_format, times, calib, rate_hz, name), out
    )
