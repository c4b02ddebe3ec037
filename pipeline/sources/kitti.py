"""KITTI odometry layout: ROOT/sequences/SEQ/{velodyne/*.bin, times.txt, calib.txt},
ROOT/poses/SEQ.txt (optional ground truth, camera-0 frame -> T_world_lidar = inv(Tr) P Tr).

Frames ``start`` .. ``end`` (both inclusive, KITTI frame numbers) can be picked; stamps are
times.txt seconds in ns as they are (KITTI times start at 0.0). The sequence is named as KITTI
names it (``04``), by ``adaptune ingest kitti`` as in a ``data`` set; the root is recorded as
an absolute path (metadata ``x.kitti_root``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.kitti_calib import read_kitti_calib
from pipeline.posefile import read_pose_file
from pipeline.sequence import SequenceInfo
from pipeline.sources.base import Frame, IngestReport, write_sequence
from pipeline.sources.ordering import natural_order
from pipeline.sources.poses import check_count, to_lidar_frame
from pipeline.sources.scanfiles import read_bin, scan_files
from pipeline.stamps import read_times


def _check_numbering(velodyne: Path, bins: list[Path]) -> None:
    """KITTI scans are 000000.bin .. N-1: line k of times.txt and of the pose file is scan k,
    so a gap (or another name) would pair scans with the wrong stamps and poses."""
    for k, path in enumerate(bins):
        if not path.stem.isdigit() or int(path.stem) != k:
            raise InputError(
                f"{velodyne}: scan {k} is {path.name}, expected {k:06d}.bin (KITTI numbers "
                "scans 0..N-1 without gaps: line k of times.txt and of the poses is scan k)"
            )


class KittiSource:
    """Scans of one KITTI odometry sequence, with ground truth where ROOT/poses/SEQ.txt exists."""

    name: ClassVar[str] = "kitti"

    def __init__(
        self,
        root: str | Path,
        seq: str,
        start: int | None = None,
        end: int | None = None,
        name: str | None = None,
    ) -> None:
        self.root = Path(root)
        self.seq = str(seq)
        self.dir = self.root / "sequences" / self.seq
        self.seq_name = name or self.seq
        velodyne = self.dir / "velodyne"
        if not velodyne.is_dir():
            raise InputError(
                f"{velodyne}: no such folder (expected ROOT/sequences/{self.seq}/velodyne)"
            )
        all_bins = natural_order(scan_files(velodyne, (".bin",)), str(velodyne))
        _check_numbering(velodyne, all_bins)
        n = len(all_bins)
        self.start = 0 if start is None else int(start)
        self.end = n - 1 if end is None else int(end)
        if not 0 <= self.start <= self.end < n:
            raise ConfigError(
                f"frame range --start {self.start} --end {self.end} is not within "
                f"0..{n - 1} of {velodyne}"
            )
        self.bins = all_bins[self.start : self.end + 1]
        self.stamps_ns = read_times(self.dir / "times.txt", n)[self.start : self.end + 1]
        self.Tr = read_kitti_calib(self.dir / "calib.txt")
        self.T_world_lidar = self._ground_truth(n)
        self.inputs = (*all_bins, self.dir / "times.txt", self.dir / "calib.txt",
                       self.root / "poses" / f"{self.seq}.txt")

    def _ground_truth(self, n: int) -> NDArray[np.float64] | None:
        path = self.root / "poses" / f"{self.seq}.txt"
        if not os.path.lexists(path):  # optional; but a FIFO, a folder... is an error
            return None
        poses = read_pose_file(path, "kitti")
        check_count(poses, n, str(self.dir / "velodyne"))
        return to_lidar_frame(poses.T_world_x[self.start : self.end + 1], self.Tr)

    def sequence_info(self) -> SequenceInfo:
        return SequenceInfo(
            name=self.seq_name,
            sensor="velodyne_hdl64e",
            source=f"kitti:{self.seq}",
            extra={
                "kitti_root": str(self.root.resolve()),
                "first_frame": str(self.start),
                "last_frame": str(self.end),
                "T_cam_lidar": json.dumps(self.Tr.ravel().tolist()),  # KITTI's Tr
                "ground_truth": "none" if self.T_world_lidar is None else
                f"pose file poses/{self.seq}.txt (camera 0, through Tr)",
            },
        )

    def expected_frames(self) -> int:
        return len(self.bins)

    def ground_truth_poses(self) -> NDArray[np.float64] | None:
        return None if self.T_world_lidar is None else self.T_world_lidar.copy()

    def frame_stamps_ns(self) -> NDArray[np.int64]:
        return np.asarray(self.stamps_ns, np.int64).copy()

    def frames(self) -> Iterator[Frame]:
        for k, path in enumerate(self.bins):
            yield Frame(
                int(self.stamps_ns[k]),
                read_bin(path),
                None if self.T_world_lidar is None else self.T_world_lidar[k],
                str(path),
            )


def ingest_kitti(
    root: str | Path,
    seq: str,
    out: str | Path,
    start: int | None = None,
    end: int | None = None,
    name: str | None = None,
) -> IngestReport:
    """KITTI sequence ``seq`` under ``root`` -> MCAP ``out``, frames start..end inclusive."""
    return write_sequence(KittiSource(root, seq, start, end, name), out)
