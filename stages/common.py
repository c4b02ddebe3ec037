"""Click options and arguments shared by the thin stage commands.

One home for each option that several commands take, so that its name, type and help read the
same everywhere: ``@params_option``, ``@sequences_option``, ``@model_argument`` ... Options
that differ only in their help text are built by ``file_option`` / ``dir_option``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])

FILE = click.Path(dir_okay=False, path_type=Path)
"""A file path (a folder is refused by click)."""
DIR = click.Path(file_okay=False, path_type=Path)
"""A folder path (a file is refused by click)."""


def file_option(flag: str, dest: str | None = None, *, help: str, required: bool = True,
                default: Path | None = None, show_default: bool = False
                ) -> Callable[[F], F]:
    """``--flag FILE`` (required unless a default is given)."""
    names = (flag, dest) if dest else (flag,)
    return click.option(*names, type=FILE, required=required and default is None,
                        default=default, show_default=show_default, help=help)


def dir_option(flag: str, dest: str | None = None, *, help: str, required: bool = True
               ) -> Callable[[F], F]:
    """``--flag DIR``."""
    names = (flag, dest) if dest else (flag,)
    return click.option(*names, type=DIR, required=required, help=help)


def compose(*decorators: Callable[[F], F]) -> Callable[[F], F]:
    """Several click decorators as one, applied in the order written (top one first)."""

    def apply(fn: F) -> F:
        for decorator in reversed(decorators):
            fn = decorator(fn)
        return fn

    return apply


params_option = file_option(
    "--params", "params_path", default=Path("params.yaml"), show_default=True,
    help="The params file (one section per stage).",
)
sequences_option = dir_option(
    "--sequences", "sequence_dir", help="Sequence folder with index.json."
)
model_argument = click.argument("model_dir", type=DIR)
sequence_argument = click.argument("sequence", type=FILE)
json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print JSON on stdout instead of a summary."
)


def algorithm_option(help: str, required: bool = False) -> Callable[[F], F]:
    """``--algorithm NAME`` (an adapter name of the registry)."""
    return click.option("--algorithm", "-a", required=required, default=None, help=help)
