"""`make bench`: every performance figure (docs/design.md, "Performance"), printed as one table.

Each ``bench/bench_*.py`` module exposes ``run() -> list[Row]``; a row gives the figure, our
measurement, the reference measured in the same run (or the paper's number), and the target.
Run one module with ``python bench/run.py ingest``. Every module runs in a process of its own.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # the modules' own `common` and `reference`, when run.py is loaded

from common import Row, format_table  # noqa: E402


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.WARNING)
    if argv[:1] == ["--module"]:  # one module, its rows as JSON on stdout (run by the loop below)
        print(json.dumps([asdict(r) for r in run_module(argv[1])]))
        return 0
    wanted = set(argv)
    rows: list[Row] = []
    for path in sorted(HERE.glob("bench_*.py")):
        name = path.stem.removeprefix("bench_")
        if wanted and name not in wanted:
            continue
        t0 = time.perf_counter()
        # every module in a fresh process: no thread, cache or import left by another one
        done = subprocess.run([sys.executable, __file__, "--module", name], check=True,
                              stdout=subprocess.PIPE, text=True)
        got = [Row(**r) for r in json.loads(done.stdout.strip().splitlines()[-1])]
        print(f"[{name}: {len(got)} figures in {time.perf_counter() - t0:.1f} s]", file=sys.stderr)
        print(format_table(got), flush=True)
        rows.extend(got)
    print("\n== all figures ==")
    print(format_table(rows))
    return 0


def run_module(name: str) -> list[Row]:
    """The rows of bench/bench_<name>.py."""
    path = HERE / f"bench_{name}.py"
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    rows: list[Row] = module.run()
    return rows


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
