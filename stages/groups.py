"""The ``adaptune`` command group's machinery: a click group whose sub-commands load lazily,
and the one place an AdaptuneError becomes one line on stderr and exit code 1 (an interrupt:
one line and exit code 130). ``stages.cli`` and ``stages.study`` build their groups with it."""

from __future__ import annotations

import importlib
from typing import Any

import click

INTERRUPTED = 130
"""The exit code of a command ended by Ctrl-C, SIGTERM or SIGHUP (128 + SIGINT, as a shell
reports Ctrl-C); every error is exit code 1."""

Registry = dict[str, tuple[str, str]]
"""Command name -> (``module:attribute`` of its click command, short help)."""


class LazyGroup(click.Group):
    """A group that imports a sub-command only when it is run or asked for help:
    ``listed`` commands show in ``--help``, ``unlisted`` ones (a callable giving a registry)
    run too."""

    def __init__(self, *args: Any, listed: Registry | None = None,
                 unlisted: Any = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.listed = listed or {}
        self.unlisted = unlisted or dict

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [n for n, (target, _) in self.listed.items() if _module_exists(target)]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        known = self.listed if name in self.listed else self.unlisted()
        if name not in known or not _module_exists(known[name][0]):
            return None
        target, short = known[name]
        module, attr = target.split(":")
        cmd = getattr(importlib.import_module(module), attr)
        cmd.short_help = cmd.short_help or short
        return cmd

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(n, self.listed[n][1]) for n in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        from pipeline.errors import AdaptuneError

        try:
            return super().invoke(ctx)
        except AdaptuneError as exc:
            click.echo(f"adaptune: error: {exc}", err=True)
            ctx.exit(1)
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM / SIGHUP (lifetime.Terminated)
            import signal

            name = signal.Signals(getattr(exc, "signum", signal.SIGINT)).name
            click.echo(f"adaptune: interrupted ({name})", err=True)
            ctx.exit(INTERRUPTED)


def _module_exists(target: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(target.split(":")[0]) is not None
