"""Click options and arguments shared by the thin stage commands.

One home for each option that several commands take, so that its name, type and help read the
same everywhere: ``@params_option``, ``@sequences_option``, ``@model_argument`` ... Options
that differ only in their help text are built by ``file_option`` / ``dir_option``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])

class NoDashPath(click.Path):
    """A click.Path that refuses ``-`` unless ``allow_dash`` (an output written as a stream:
    ``-`` is stdout, ``pipeline.io_utils.STDOUT``); anywhere else ``-`` would silently be a
    file of that name (``metric rte SEQ -`` scored a stale one). A path the kernel cannot take
    (a name past 255 bytes) is one ConfigError naming the limit
    (``pipeline.io_utils.check_path_length``), not an OSError later."""

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        where = (param.get_error_hint(ctx) if param is not None and ctx is not None
                 else "a path")  # e.g. '--out' or 'ESTIMATE'
        if value in ("-", b"-"):
            if not self.allow_dash:
                refuse_dash(where)
        elif isinstance(value, str | Path):
            from pipeline.io_utils import check_path_length

            check_path_length(value, f"path of {where}")
        return super().convert(value, param, ctx)


def refuse_dash(where: str) -> None:
    """ConfigError: ``-`` given for ``where``, a file path that is not stdin or stdout."""
    from pipeline.errors import ConfigError

    raise ConfigError(f"{where}: '-' (stdin, stdout) is not read or written here (stdout is "
                      "an output file's --out -, stdin query's SQL); give a file path (./- "
                      "for a file named -)")


FILE = NoDashPath(dir_okay=False, path_type=Path)
"""A file path (a folder is refused by click, ``-`` by NoDashPath)."""
OUT_FILE = NoDashPath(dir_okay=False, allow_dash=True, path_type=Path)
"""A file a command writes as a stream: ``-`` is standard output (written through,
``pipeline.io_utils.atomic_path``), as a FIFO or a device is."""
DIR = NoDashPath(file_okay=False, path_type=Path)
"""A folder path (a file is refused by click, ``-`` by NoDashPath)."""
PATH = NoDashPath(path_type=Path)
"""A file or folder path (``-`` refused)."""


def file_option(flag: str, dest: str | None = None, *, help: str, required: bool = True,
                default: Path | None = None, show_default: bool = False
                ) -> Callable[[F], F]:
    """``--flag FILE`` (required unless a default is given)."""
    names = (flag, dest) if dest else (flag,)
    return click.option(*names, type=FILE, required=required and default is None,
                        default=default, show_default=show_default, help=help)


def out_option(dest: str | None = None, *, help: str) -> Callable[[F], F]:
    """``--out FILE``, the one file a command writes: ``-`` is standard output."""
    names = ("--out", dest) if dest else ("--out",)
    return click.option(*names, type=OUT_FILE, required=True,
                        help=f"{help.rstrip('.')} (- for stdout).")


def refuse_json_on_stdout(out: Path, as_json: bool) -> None:
    """ConfigError when both ``--out -`` and ``--json`` would write stdout (the data and the
    summary mixed in one stream)."""
    if as_json and str(out) == "-":
        from pipeline.errors import ConfigError

        raise ConfigError("--out - and --json both write stdout; give --out FILE, or leave "
                          "--json out (the summary then goes to stderr)")


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


def _params_path(ctx: click.Context, param: click.Parameter, value: Path | None) -> Path | None:
    """--params as given; without it ./params.yaml where there is one, else None (defaults)."""
    if value is not None:
        return value
    default = Path("params.yaml")
    return default if default.exists() else None


params_option = click.option(
    "--params", "params_path", type=FILE, default=None, callback=_params_path,
    help="The params file, one section per stage [default: ./params.yaml if there is one, "
    "else every section at its defaults].",
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


def read_text_argument(value: str, what: str) -> str:
    """``value`` itself, or all of stdin when it is ``-`` (ConfigError when that is empty)."""
    if value != "-":
        return value
    from pipeline.errors import ConfigError

    text = sys.stdin.read()
    if not text.strip():
        raise ConfigError(f"{what} from stdin (-): got nothing")
    return text


def write_output(data: bytes) -> None:
    """Write a command's data (the result, not a summary) to stdout, flushed: the one writer of
    stdout. OutputError (one line) when stdout takes no more: a reader that closed the pipe
    (EPIPE), a full device (ENOSPC); stdout then goes to /dev/null, so that the interpreter's
    last flush at exit raises nothing more."""
    from pipeline.errors import OutputError

    try:
        sys.stdout.flush()
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
    except OSError as exc:
        _stdout_to_devnull()
        raise OutputError(f"stdout: cannot write the output ({exc.strerror or exc})") from None


def echo_output(text: str) -> None:
    """``text`` and a line break as a command's data on stdout (``write_output``)."""
    write_output(f"{text}\n".encode())


def _stdout_to_devnull() -> None:
    """Point the stdout file descriptor (and what Python still buffers for it) at /dev/null."""
    import io
    import os

    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, io.UnsupportedOperation):  # not a real file (a test's)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


def report(summary: dict[str, Any], line: str, as_json: bool) -> None:
    """A command's summary: JSON on stdout with ``--json``, else ``line`` on stderr."""
    if as_json:
        import json

        echo_output(json.dumps(summary, indent=1, default=str))
    else:
        click.echo(line, err=True)


def model_run_options(out_help: str) -> Callable[[F], F]:
    """``MODEL_DIR SEQUENCE --out FILE [--algorithm NAME] [--json]``: what select and live take."""
    return compose(model_argument, sequence_argument, out_option(help=out_help),
                   algorithm_option("Refuse a model made for another algorithm."), json_option)


def report_selection(summary: dict[str, Any], as_json: bool) -> None:
    """The summary of select and live: frames, selections, parameter changes (one wording)."""
    report(summary, f"{summary['algorithm']}: {summary['frames']} frames, "
           f"{summary['selections']} selections, {summary['changes']} parameter changes -> "
           f"{summary['out']}", as_json)
