"""Environment descriptors: the seam every descriptor implements, and the registry.

A descriptor turns one scan (points in the sensor frame [m]) into a fixed-width vector of
non-negative values (a histogram: the PCA takes its square root, ``pipeline.pca``). Its width
follows from its settings (``size``) and is written wherever the values go: the descriptors
Parquet schema (``schemas.arrow.descriptors_schema``), the results database, pca.json and the
artifact manifest (``to_json``). A new descriptor is one module implementing ``Descriptor`` plus
one line in ``DESCRIPTORS``; tests/test_descriptor_contract.py runs over every one of them.

This package's import stays light (numpy; numba kernels on first use): the runtime loads it.
The descriptors of a whole data set (the ``descriptors`` stage) are ``.dataset``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pipeline.descriptors.ndt_histogram import NdtHistogram
from pipeline.errors import ConfigError


@runtime_checkable
class Descriptor(Protocol):
    """One environment descriptor with its settings (module docstring)."""

    type: ClassVar[str]
    manifest_schema: ClassVar[dict[str, Any]]
    """The JSON Schema of ``to_json``'s settings (the artifact's descriptor block)."""

    @property
    def size(self) -> int:
        """The width: how many values ``describe`` returns."""
        ...

    def describe(self, points_lidar: NDArray[np.floating]) -> NDArray[np.float32]:
        """(N, 3|4) points [m], sensor frame -> (size,) non-negative float32 values."""
        ...

    def value_names(self) -> list[str]:
        """A readable name for each of the ``size`` values."""
        ...

    def to_json(self) -> dict[str, Any]:
        """``type``, the settings and ``size``: what ``descriptor_from_json`` reads back."""
        ...


DESCRIPTORS: dict[str, Callable[..., Descriptor]] = {
    "ndt_histogram": NdtHistogram,
}
"""Every registered descriptor by type, built from its settings; the first is the default."""
DEFAULT_DESCRIPTOR = next(iter(DESCRIPTORS))


def make_descriptor(type_name: str, settings: Mapping[str, Any] | None = None) -> Descriptor:
    """The descriptor ``type_name`` with ``settings``; ConfigError naming an unknown type or
    setting, or the rule a value breaks."""
    factory = DESCRIPTORS.get(type_name)
    if factory is None:
        raise ConfigError(f"unknown descriptor type {type_name!r} (known: "
                          f"{', '.join(DESCRIPTORS)})")
    try:
        return factory(**dict(settings or {}))
    except TypeError as exc:
        raise ConfigError(f"descriptor {type_name}: {exc}") from None


def descriptor_from_json(data: Mapping[str, Any]) -> Descriptor:
    """The descriptor of a ``to_json`` record (one without ``type`` is the default type);
    ConfigError when its recorded ``size`` does not match its settings."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"descriptor settings must be an object, got {data!r}")
    settings = {k: v for k, v in data.items() if k not in ("type", "size")}
    descriptor = make_descriptor(str(data.get("type", DEFAULT_DESCRIPTOR)), settings)
    if "size" in data and data["size"] != descriptor.size:
        raise ConfigError(f"descriptor size {data['size']!r} does not match its settings "
                          f"({descriptor.size})")
    return descriptor
