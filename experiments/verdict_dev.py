"""Selector variants on the coverage model's dev suites (issue 29; verdict-protocol.md).

Not a `make bench` module (tens of minutes): ``python experiments/verdict_dev.py --project verdict
[--family id] [--worlds N] [--variants default,paper,...]``, after the coverage model's training
stages ran in ``--project`` (``dvc repro verdict/dvc.yaml:surrogate`` at 1ea832c or before:
since 962a54d the verdict pipeline builds one portfolio model per sensor, models/<sensor>, whose
variants experiments/tuning_suite.py studies). Every choice of the selector is made here, on
the **dev** suites, never on the test suites.

It reads the project's params.yaml (its ``verdict`` section with ``suite`` set to ``dev``), its
model/, results/fixed, results/adaptune.duckdb and data/pca; fits the surrogate variants a
variant needs (``surrogate.k``, ``surrogate.novelty_fallback``) into ``<project>/dev/models/``;
then runs every world of the family's dev suite once, baseline and fixed once and every
variant's adaptive schedule on the same decoded world (``studies.suites.runner.run_suite`` with
one adaptive setting per variant), each on every replica; writes ``<project>/dev/<family>/``
(the worlds' runs) and ``<project>/dev/<family>.json`` (the suite's summary per variant), and
prints one row per variant.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PORTFOLIO: dict[str, Any] = {"rows": "portfolio", "n_sobol": 0, "w_x": 1000.0}
"""The portfolio's rows, its members as the only candidates, members kept apart (w_x)."""

VARIANTS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    # name: (surrogate section changes: a refit; select settings changes)
    "default": ({}, {}),
    "paper": ({"k": 5}, {"window": 1}),
    "k_80": ({"k": 80}, {}),  # ISAC-like: the mean over many more neighbours, near clusters
    "fallback_fixed": ({"novelty_fallback": "fixed"}, {}),
    "trust_0.25": ({}, {"trust_radius": 0.25}),
    "fallback_fixed_trust_0.25": ({"novelty_fallback": "fixed"}, {"trust_radius": 0.25}),
    "fallback_fixed_risk_0.5": ({"novelty_fallback": "fixed"}, {"risk": 0.5}),
    "fallback_fixed_anchor_0.1": ({"novelty_fallback": "fixed"}, {"anchor_margin": 0.1}),
    # the portfolio selector (pipeline.portfolio): the members only, each predicted from
    # its own runs at the k nearest training frames (needs the rte stage's --portfolio)
    "portfolio_k20": ({**PORTFOLIO, "k": 20}, {"refine_iters": 0}),
    "portfolio_k100": ({**PORTFOLIO, "k": 100}, {"refine_iters": 0}),
    "portfolio_k350": ({**PORTFOLIO, "k": 350}, {"refine_iters": 0}),
    "portfolio_k1000": ({**PORTFOLIO, "k": 1000}, {"refine_iters": 0}),  # a 5x tuning set
}


def variant_model(project: Path, name: str, changes: dict[str, Any]) -> Path:
    """The project's model, or one refitted with the surrogate ``changes`` (cached)."""
    from pipeline.config import load_section
    from pipeline.descriptors.dataset import DescriptorsSection
    from pipeline.surrogates.fit import ModelInputs, build_model
    from pipeline.surrogates.section import SurrogateSection
    from pipeline.tuning.table import read_space

    if not changes:
        return project / "model"
    out = project / "dev" / "models" / name
    if not (out / "manifest.json").is_file():
        params = project / "params.yaml"
        section = load_section(params, "surrogate", SurrogateSection).model_copy(update=changes)
        descriptors = load_section(params, "descriptors", DescriptorsSection)
        build_model(ModelInputs(project / "results" / "adaptune.duckdb", project / "data" / "pca"),
                    out, section, descriptors,
                    lambda algo: read_space(project / "results" / "trials", algo), None)
    return out


def main() -> None:
    from pipeline.report.outputs import write_json
    from studies.verdict.report import load_settings, suite_inputs
    from studies.suites.runner import AdaptiveSetting, run_suite
    from studies.verdict.summary import suite_metrics
    from studies.verdict.worlds import suite_worlds

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--project", type=Path, default=Path("verdict"))
    parser.add_argument("--family", choices=["id", "ood"], default="id")
    parser.add_argument("--worlds", type=int, default=None)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    args = parser.parse_args()
    project: Path = args.project
    params = project / "params.yaml"
    section, settings = load_settings(params)
    draw = section.suites.draw(args.family)
    if args.worlds is not None:
        draw = draw.model_copy(update={"worlds": args.worlds})
    section = section.model_copy(update={"suite": "dev", "suites": section.suites.model_copy(
        update={args.family: draw})})
    inputs, study = suite_inputs(project / "model", project / "results" / "fixed", section,
                                 settings)
    names = args.variants.split(",")
    adaptive = {f"adaptive:{n}": AdaptiveSetting(
        variant_model(project, n, VARIANTS[n][0]),
        settings.selection.replace(**VARIANTS[n][1])) for n in names}
    inputs = dataclasses.replace(inputs, adaptive=adaptive)
    worlds = suite_worlds(section, args.family, settings.template)
    results = run_suite(worlds, inputs, project / "dev" / args.family, section.workers)
    header = {"family": args.family, "suite": "dev", "seed_root": section.root(args.family),
              "replicas": section.replicas, "fixed_study": study}
    summaries = {n: suite_metrics(results, header, section.failure_pct, section.confidence,
                                  section.resamples, section.root(args.family), f"adaptive:{n}")
                 for n in names}
    write_json(project / "dev" / f"{args.family}.json", summaries)
    print(f"{args.family} dev suite, {len(results)} worlds, {section.replicas + 1} runs a "
          "setting; geometric means (95 % interval), win rate, pooled failure rate")
    for n, m in summaries.items():
        print(summary_row(n, m))
    print(json.dumps({"log_spread_adaptive_vs_fixed": {
        n: m["ratios"]["adaptive_vs_fixed"]["log_spread"] for n, m in summaries.items()}}))


def summary_row(name: str, m: dict[str, Any]) -> str:
    """One variant's line: its ratios with intervals, wins and worst against fixed, pooled
    failure rates and what its selector did (``m``: ``suite_metrics`` of the variant)."""
    r, sel, pooled = m["ratios"], m["selector"], m["pooled"]
    cells = [f"{k.removeprefix('adaptive_vs_')} {_g(r[k])}"
             for k in ("adaptive_vs_fixed", "adaptive_vs_baseline", "adaptive_vs_best")]
    f = r["adaptive_vs_fixed"]
    return (f"{name:28s} " + "; ".join(cells)
            + f"; wins vs fixed {f['wins']}/{f['worlds']}, worst {f['worst']:.2f}"
            + f"; failures {pooled[f'adaptive:{name}']['failure_rate']:.3f}"
            + f" (fixed {pooled['fixed']['failure_rate']:.3f}, baseline "
            + f"{pooled['baseline']['failure_rate']:.3f})"
            + f"; changes {sel['changes']:.1f}, unfamiliar {sel['novel_share']:.2f}, "
            + f"edge {sel['edge_share']:.2f}")


def _g(s: dict[str, Any]) -> str:
    from studies.docs.markdown import number

    return f"{number(s['geomean'], 2)} ({number(s['low'], 2)}-{number(s['high'], 2)})"


if __name__ == "__main__":
    main()
