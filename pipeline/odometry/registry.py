"""The explicit registry of odometry adapters (docs/design.md, "Seams").

``ADAPTERS`` maps a name to a factory ``(**options) -> Adapter``. Factories import their
module lazily, so that listing the names never imports small_gicp or kiss_icp.
Options are adapter-specific settings that are not tuned (e.g. ``source_voxel_m`` of ``ndt``,
``command`` of ``command``); each adapter validates its own and rejects unknown ones.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.errors import ConfigError
from pipeline.odometry.base import Adapter


def _ndt(**options: Any) -> Adapter:
    from pipeline.odometry.ndt import NdtAdapter

    return NdtAdapter(**options)


def _gicp(**options: Any) -> Adapter:
    from pipeline.odometry.gicp import GicpAdapter

    return GicpAdapter(**options)


def _kiss_icp(**options: Any) -> Adapter:
    from pipeline.odometry.kiss import KissIcpAdapter

    return KissIcpAdapter(**options)


def _command(**options: Any) -> Adapter:
    from pipeline.odometry.command import CommandAdapter

    return CommandAdapter(**options)


ADAPTERS: dict[str, Callable[..., Adapter]] = {
    "ndt": _ndt,
    "gicp": _gicp,
    "kiss_icp": _kiss_icp,
    "command": _command,
}


def adapter_names() -> list[str]:
    """Names of every registered adapter, in registry order."""
    return list(ADAPTERS)


def get_adapter(name: str, **options: Any) -> Adapter:
    """A new adapter ``name`` configured with ``options``; ConfigError for an unknown name."""
    factory = ADAPTERS.get(name)
    if factory is None:
        raise ConfigError(f"unknown odometry algorithm {name!r} (known: {', '.join(ADAPTERS)})")
    return factory(**options)
