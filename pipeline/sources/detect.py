"""What a recording is: its ``data.sources`` entry, found from its path (``adaptune init``).

``recording_entry(path, given)`` tells the kind from the path (``recording_kind``), finds what
the source needs where it is unambiguous, then opens the recording with its source, so that
everything ambiguous or missing is one error now, naming what to give:

- a bag or MCAP: its only PointCloud2 topic and its only PoseStamped / Odometry topic (the
  source's own rules, pipeline.sources.rosbag);
- a scan folder: the files beside the scans: ``times.txt`` (stamps), a KITTI ``calib.txt``
  (the extrinsic, as for KITTI's camera poses) and the one other text file that reads as a
  pose file (KITTI, TUM, EuRoC or 4x4 blocks);
- a KITTI sequence folder ``ROOT/sequences/NN``: the root and the sequence (its ground truth is
  ``ROOT/poses/NN.txt``); a KITTI root (``ROOT`` with ``sequences/`` and ``poses/``) is its
  sequences that have ground truth (``recordings_of``), each a recording.

Every recording must have ground truth that runs longer than its RTE length, its own
``length_m`` (a list file's option) or else ``length_m`` (base.length_m), or with ``pieces``
one piece that does (``pipeline.sources.dataset.plan_source``), read without decoding its
scans. A
text file beside a folder's scans that is not a pose file of any format is named with the
reason when the folder has no other (not dropped, to end in "no ground truth found").
Options in ``given`` (the keys of a ``data`` source) win over what is found.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pipeline.errors import ConfigError, InputError
from pipeline.sources.scanfiles import SCAN_SUFFIXES

KINDS_HELP = ("a ROS 1 .bag file, a ROS 2 bag folder (metadata.yaml), an .mcap file, a folder of "
              ".bin / .pcd / .ply scans, a KITTI ROOT/sequences/NN folder or a KITTI ROOT")
POSE_SUFFIXES = (".txt", ".csv", ".tum")
"""Files of a scan folder that may be its pose file."""


def is_kitti_root(path: Path) -> bool:
    """Whether ``path`` is a KITTI odometry root: a folder with ``sequences/`` and ``poses/``."""
    return path.is_dir() and (path / "sequences").is_dir() and (path / "poses").is_dir()


def recordings_of(path: Path) -> list[Path]:
    """The recordings at ``path``: a KITTI root's sequence folders that have ground truth
    (``ROOT/sequences/NN`` with ``ROOT/poses/NN.txt``, in name order); else ``path`` itself.
    ConfigError for a KITTI root without one."""
    if not is_kitti_root(path):
        return [path]
    found = sorted(p for p in (path / "sequences").iterdir()
                   if (p / "velodyne").is_dir() and (path / "poses" / f"{p.name}.txt").is_file())
    if not found:
        raise ConfigError(f"{path}: a KITTI root without a sequence that has ground truth "
                          "(sequences/NN/velodyne with poses/NN.txt)")
    return found


def recording_kind(path: Path) -> str:
    """The source kind of the recording at ``path``: rosbag, mcap, kitti or folder;
    InputError when it is none of them."""
    if not path.exists():
        raise InputError(f"{path}: no such recording")
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "rosbag"
        if (path / "velodyne").is_dir() and path.parent.name == "sequences":
            return "kitti"
        if any(p.suffix.lower() in SCAN_SUFFIXES for p in path.iterdir()):
            return "folder"
    elif path.suffix == ".bag" or (
            path.suffix in (".mcap", ".db3") and (path.parent / "metadata.yaml").is_file()):
        return "rosbag"
    elif path.suffix == ".mcap":
        return "mcap"
    raise InputError(f"{path}: cannot tell what kind of recording this is (expected "
                     f"{KINDS_HELP}); give its kind")


def recording_entry(path: str | Path, given: Mapping[str, Any] | None = None,
                    length_m: float | None = None) -> dict[str, Any]:
    """The ``data.sources`` entry of the recording at ``path`` (module docstring), checked by
    opening it (and its ground truth's length against ``length_m`` when given); ``path`` as
    given unless the kind moves it (a ROS 2 bag's file -> its folder, a KITTI sequence folder
    -> its root)."""
    from pydantic import TypeAdapter, ValidationError

    from pipeline.config import format_validation_error
    from pipeline.sources.dataset import SourceEntry, plan_source

    path = Path(path)
    given = dict(given or {})
    kind = given.pop("kind", None) or recording_kind(path)
    entry: dict[str, Any] = {"kind": kind, "path": str(path)}
    if kind == "rosbag" and path.is_file() and path.suffix != ".bag":
        entry["path"] = str(path.parent)
    if kind == "kitti" and "sequences" not in given:
        entry |= {"path": str(path.parent.parent), "sequences": [path.name]}
    if kind == "folder":
        entry |= folder_files(path, given)
    entry |= given
    try:
        checked = TypeAdapter(SourceEntry).validate_python(entry)
    except ValidationError as exc:
        raise ConfigError(f"{path}: {format_validation_error('', exc)}") from None
    sources = checked.open()
    for source in sources:
        if not plan_source(checked, source, length_m, str(path)).has_ground_truth:
            raise ConfigError(f"{path}: no ground truth found (tuning needs it): give its "
                              "gt_topic (with gt_child_frame for TF) or a pose file (poses)")
    found = {key: getattr(sources[0], attr, None)
             for key, attr in (("topic", "topic"), ("gt_topic", "gt_topic"))}
    return entry | {k: v for k, v in found.items() if v is not None and k not in given}


def folder_files(folder: Path, given: Mapping[str, Any]) -> dict[str, str]:
    """``times``, ``extrinsic`` and ``poses`` of a scan folder, from the files beside its scans
    (module docstring), where not ``given``; ConfigError when two files could be the poses."""
    from pipeline.kitti_calib import has_kitti_calib
    from pipeline.posefile import read_pose_file

    found: dict[str, str] = {}
    others = sorted(p for p in folder.iterdir()
                    if p.is_file() and p.suffix.lower() in POSE_SUFFIXES)
    for p in others:
        if p.name == "times.txt":
            found["times"] = str(p)
        elif p.suffix == ".txt" and has_kitti_calib(p.read_text(errors="replace")):
            found["extrinsic"] = str(p)
    candidates, refused = [], []
    for p in others:
        if str(p) in found.values():
            continue
        try:
            read_pose_file(p)
        except InputError as exc:
            refused.append(f"{p.name}: {str(exc).removeprefix(f'{p}: ')}")
            continue
        candidates.append(p)
    if "poses" not in given:
        if len(candidates) > 1:
            raise ConfigError(f"{folder}: {len(candidates)} files read as poses "
                              f"({', '.join(p.name for p in candidates)}); give the one that is")
        if refused and not candidates:
            raise ConfigError(f"{folder}: no pose file beside the scans reads as one: "
                              f"{'; '.join(refused)}; give poses (and poses_format)")
    if candidates:
        found["poses"] = str(candidates[0])
    return {k: v for k, v in found.items() if k not in given}
