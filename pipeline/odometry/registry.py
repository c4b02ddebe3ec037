"""The explicit registry of odometry adapters (docs/design.md, "Seams").

``ADAPTERS`` maps a name to a loader of its adapter class (``(**options) -> Adapter``), which
imports its module lazily, so that listing the names never imports small_gicp or kiss_icp.
Options are adapter-specific settings that are not tuned (e.g. ``source_voxel_m`` of ``ndt``,
``command`` of ``command``): the class's ``options_model`` (``option_names``); each adapter
validates its own and rejects unknown ones.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from pipeline.errors import ConfigError
from pipeline.odometry.base import Adapter, ParameterSpace, with_space


def _ndt() -> type[Adapter]:
    from pipeline.odometry.ndt import NdtAdapter

    return NdtAdapter


def _gicp() -> type[Adapter]:
    from pipeline.odometry.gicp import GicpAdapter

    return GicpAdapter


def _kiss_icp() -> type[Adapter]:
    from pipeline.odometry.kiss import KissIcpAdapter

    return KissIcpAdapter


def _command() -> type[Adapter]:
    from pipeline.odometry.command import CommandAdapter

    return CommandAdapter


ADAPTERS: dict[str, Callable[[], type[Adapter]]] = {
    "ndt": _ndt,
    "gicp": _gicp,
    "kiss_icp": _kiss_icp,
    "command": _command,
}


OPTION_SPACES = frozenset({"command"})
"""Registered adapters whose tuned parameters their options declare (``command``'s ``space``):
they have no space of their own to check a model's against."""


def declared_space(name: str) -> list[tuple[str, str]] | None:
    """(name, kind) of every parameter the registered adapter ``name`` tunes, in its order:
    what a model's or a study's parameter space must name (``with_space``'s rule); None for an
    adapter whose options declare them (``OPTION_SPACES``) or a plugin factory (module:attr).
    ConfigError for an unknown name."""
    if ":" in name or name in OPTION_SPACES:
        return None
    return [(s.name, s.kind) for s in get_adapter(name).space.specs]


def adapter_names() -> list[str]:
    """Names of every registered adapter, in registry order."""
    return list(ADAPTERS)


def adapter_class(name: str) -> Any:
    """The adapter class registered as ``name``; ConfigError for an unknown name."""
    load = ADAPTERS.get(name)
    if load is None:
        raise ConfigError(f"unknown odometry algorithm {name!r} (known: {', '.join(ADAPTERS)})")
    return load()


def get_adapter(name: str, **options: Any) -> Adapter:
    """A new adapter ``name`` configured with ``options``; ConfigError for an unknown name."""
    adapter: Adapter = adapter_class(name)(**options)
    return adapter


def option_names(name: str) -> list[str]:
    """The untuned options the registered adapter ``name`` takes (its ``options_model``)."""
    return list(adapter_class(name).options_model.model_fields)


def build_adapter(name: str, options: Mapping[str, Any] | None = None,
                  space: ParameterSpace | list[dict[str, Any]] | None = None) -> Adapter:
    """The adapter every stage runs: ``name`` (a registry name, or a factory ``module:attr``
    that tests and plugins use) with its untuned ``options`` (params
    ``trials.adapter_options``) and, when given, ``space`` (a ParameterSpace or its JSON: the
    space a study searched, stored with its trials and in the model) in place of its built-in
    one. ConfigError for an unknown name or option."""
    options = dict(options or {})
    if ":" in name:
        import importlib

        module, attr = name.split(":", 1)
        adapter: Adapter = getattr(importlib.import_module(module), attr)(**options)
    else:
        adapter = get_adapter(name, **options)
    if space is None:
        return adapter
    return with_space(adapter, space if isinstance(space, ParameterSpace)
                      else ParameterSpace.from_json(space))
