"""Ingest sources: every input kind adaptune turns into a sequence MCAP.

``SOURCES`` is the explicit registry (name -> Source class, see base.Source); each source has
one function ``ingest_<name>(..., out) -> IngestReport``. Heavy readers (rosbags, open3d) are
imported inside the functions that need them.
"""

from __future__ import annotations

from pipeline.errors import ConfigError
from pipeline.sources.base import Frame, IngestReport, Source, write_sequence
from pipeline.sources.folder import FolderSource, ingest_folder
from pipeline.sources.kitti import KittiSource, ingest_kitti
from pipeline.sources.mcap_file import McapSource, ingest_mcap
from pipeline.sources.rosbag import RosbagSource, ingest_rosbag

SOURCES: dict[str, type[Source]] = {
    KittiSource.name: KittiSource,
    RosbagSource.name: RosbagSource,
    FolderSource.name: FolderSource,
    McapSource.name: McapSource,
}


def source_names() -> list[str]:
    """Names of the registered sources."""
    return sorted(SOURCES)


def get_source(name: str) -> type[Source]:
    """The Source class registered as ``name``; ConfigError listing the known names otherwise."""
    try:
        return SOURCES[name]
    except KeyError:
        raise ConfigError(f"unknown source {name!r} (known: {', '.join(source_names())})") from None


__all__ = [
    "SOURCES",
    "FolderSource",
    "Frame",
    "IngestReport",
    "KittiSource",
    "McapSource",
    "RosbagSource",
    "Source",
    "get_source",
    "ingest_folder",
    "ingest_kitti",
    "ingest_mcap",
    "ingest_rosbag",
    "source_names",
    "write_sequence",
]
