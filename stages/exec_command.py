"""``adaptune exec -- COMMAND ...``: run any command in adaptune's pinned CPU dispatch.

The ``adaptune`` executable has already re-executed itself in the pinned environment
(``pipeline.dispatch``) when this runs, so COMMAND inherits it: numpy, OpenBLAS, glibc's libm
and numba pick the same code on every machine, and library code run by COMMAND (the test
suite, a bench or an experiment script) gives the numbers the stages give
(docs/design.md, "Same numbers on every machine").
"""

from __future__ import annotations

import os

import click


@click.command(context_settings={"ignore_unknown_options": True,
                                 "allow_interspersed_args": False})
@click.argument("command", nargs=-1, required=True, type=click.UNPROCESSED)
def exec_command(command: tuple[str, ...]) -> None:
    """Run COMMAND with adaptune's pinned CPU dispatch (the same numbers on every machine)."""
    from pipeline.errors import InputError

    try:
        os.execvp(command[0], list(command))
    except OSError as exc:
        raise InputError(f"cannot run {command[0]!r}: {exc.strerror}") from None
