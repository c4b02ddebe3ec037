"""Run several ``adaptune`` commands in one process, in order: ``python -m helpers.run_steps
STEPS_JSON`` (a JSON list of argument lists), in the working directory, with the environment it
was started in. Started by ``adaptune exec``, the process holds the pinned CPU dispatch as each
``adaptune`` process would; tests/test_same_numbers.py runs its pipeline this way, one process a
CPU setting instead of one a command. The first command that fails ends it (its exception)."""

from __future__ import annotations

import json
import sys


def run(steps: list[list[str]]) -> None:
    from stages.cli import main

    for step in steps:
        main.main(step, prog_name="adaptune", standalone_mode=False)


if __name__ == "__main__":
    run(json.loads(sys.argv[1]))
