"""Two runs of one verdict suite, paired by world (the gate of a change on the verdict's dev
suite; docs/results/verdict-protocol.md, "Two arms of one suite").

``python experiments/verdict_arms.py REFERENCE.json CANDIDATE.json [--json OUT]``: both are a
suite's metrics (``verdict/metrics/<family>.json``) on the same worlds, e.g. the id dev suite
after whole trials (the reference) and after ``trials.fidelity: halving`` (the candidate).
Prints, per ratio, both arms' geometric means with their 95 % intervals and whether the
candidate is worse beyond the reference's interval; per setting, the paired ratio candidate /
reference of the per-world medians with its interval (``studies.verdict.arms``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _fmt(e: dict[str, float | None]) -> str:
    v, lo, hi = (e.get(k) for k in ("value" if "value" in e else "geomean", "low", "high"))
    if v is None:
        return "-"
    return f"{v:.2f}" + (f" ({lo:.2f}-{hi:.2f})" if lo is not None and hi is not None else "")


def main(argv: list[str] | None = None) -> None:
    from pipeline.errors import AdaptuneError

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reference", type=Path)
    parser.add_argument("candidate", type=Path)
    parser.add_argument("--json", type=Path, default=None, help="write the comparison here")
    args = parser.parse_args(argv)
    try:
        compare(args.reference, args.candidate, args.json)
    except (AdaptuneError, OSError, ValueError) as exc:  # ValueError: a file that is not JSON
        print(f"verdict_arms: error: {exc}", file=sys.stderr)
        sys.exit(1)


def compare(reference: Path, candidate: Path, out: Path | None) -> None:
    """Print the comparison of the two suite metrics files (module docstring); write it as
    JSON to ``out`` when given."""
    from pipeline.outputs import write_json
    from studies.verdict.arms import compare_arms

    result = compare_arms(json.loads(reference.read_text()), json.loads(candidate.read_text()))
    print(f"{result['family']} {result['suite']} suite, {result['worlds']} worlds")
    print("| ratio | reference | candidate | worse beyond the interval |\n|---|---|---|---|")
    for name, r in result["ratios"].items():
        print(f"| {name} | {_fmt(r['reference'])} | {_fmt(r['candidate'])} | "
              f"{'yes' if r['worse_beyond_interval'] else 'no'} |")
    print("\n| setting | candidate / reference, paired by world |\n|---|---|")
    for setting, e in result["paired"].items():
        print(f"| {setting} | {_fmt(e)} |")
    if out is not None:
        write_json(out, result)


if __name__ == "__main__":
    main()
