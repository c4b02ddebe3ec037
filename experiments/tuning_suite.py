"""The portfolio tuned on the tuning suite, one model per sensor, on the ID dev suite (issue 29;
docs/results/selector-dev.md, "The portfolio on a tuning suite").

Not a `make bench` module (an hour and more). The headroom split (experiments/headroom_controls.py)
found the in-distribution headroom per environment *and sensor* among long mixed worlds, while
the portfolio's 350-frame single-environment training sequences do not carry it over. This
study tunes the portfolio on the tuning suite (``pipeline.verdict.tuning``: worlds drawn as the
in-distribution suites draw theirs, from the frozen root ``verdict.tuning.seed_root``) and keys
the choice on the sensor: a deployment knows its sensor, so each sensor gets its own model.

In a copy P of the coverage model's project (its params.yaml, results/fixed):

    adaptune tuning-suite --out data/tune
    adaptune descriptors --sequences data/tune --out data/descriptors.parquet \
        --environment data/environment.parquet --pca data/pca
    for s in hdl32 hdl64: adaptune portfolio --sequences data/tune --split $s \
        --fixed results/fixed --out results/portfolio_$s
      adaptune rte --sequences data/tune --portfolio results/portfolio_$s \
        --descriptors data/descriptors.parquet --environment data/environment.parquet \
        --db results/$s.duckdb
    python experiments/tuning_suite.py --project P --worlds 12 --k 1000,3000

The last step fits per sensor and k the portfolio surrogate into P/dev/models/k<k>/<sensor>/,
runs the ID dev suite's worlds (baseline, fixed and every k on every replica;
``pipeline.verdict.runs.run_suite``, each world with its sensor's model), writes P/dev/tune/ and
P/dev/tune.json and prints one row per k.
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
"""As experiments/verdict_dev.py: the members as the only candidates, kept apart."""


def sensor_model(project: Path, sensor: str, k: int) -> Path:
    """The portfolio surrogate with ``k`` neighbours fitted on ``sensor``'s tuning worlds."""
    from pipeline.config import load_section
    from pipeline.descriptors.dataset import DescriptorsSection
    from pipeline.surrogates.fit import ModelInputs, build_model
    from pipeline.surrogates.section import SurrogateSection
    from pipeline.tuning.table import read_space

    out = project / "dev" / "models" / f"k{k}" / sensor
    if not (out / "manifest.json").is_file():
        params = project / "params.yaml"
        section = load_section(params, "surrogate", SurrogateSection).model_copy(
            update={**PORTFOLIO, "k": k})
        descriptors = load_section(params, "descriptors", DescriptorsSection)
        build_model(ModelInputs(project / "results" / f"{sensor}.duckdb", project / "data" / "pca"),
                    out, section, descriptors,
                    lambda algo: read_space(project / "results" / "fixed", algo), None)
    return out


def dev(project: Path, n_worlds: int | None, ks: list[int]) -> None:
    """The ID dev suite, each world with its sensor's model of every k; print and write."""
    from pipeline.report.outputs import write_json
    from pipeline.verdict.report import load_settings, suite_inputs
    from pipeline.verdict.runs import AdaptiveSetting, run_suite
    from pipeline.verdict.summary import suite_metrics
    from pipeline.verdict.worlds import suite_worlds

    section, settings = load_settings(project / "params.yaml")
    draw = section.suites.id
    if n_worlds is not None:
        draw = draw.model_copy(update={"worlds": n_worlds})
    section = section.model_copy(update={"suite": "dev", "suites": section.suites.model_copy(
        update={"id": draw})})
    inputs, study = suite_inputs(None, project / "results" / "fixed", section, settings)
    worlds = suite_worlds(section, "id", settings.template)
    selection = settings.selection.replace(refine_iters=0)
    for k in ks:
        for sensor in sorted({w.spec.sensor for w in worlds}):
            sensor_model(project, sensor, k)
    adaptive = {f"adaptive:k{k}": AdaptiveSetting(project / "dev" / "models" / f"k{k}",
                                                  selection) for k in ks}
    results = run_suite(worlds, dataclasses.replace(inputs, adaptive=adaptive),
                        project / "dev" / "tune", section.workers)
    header = {"family": "id", "suite": "dev", "seed_root": section.root("id"),
              "tuning_root": section.tuning.seed_root, "replicas": section.replicas,
              "fixed_study": study}
    summaries = {f"k{k}": suite_metrics(results, header, section.failure_pct, section.confidence,
                                        section.resamples, section.root("id"), f"adaptive:k{k}")
                 for k in ks}
    write_json(project / "dev" / "tune.json", summaries)
    print(f"id dev suite, {len(results)} worlds, {section.replicas + 1} runs a setting, "
          "per-sensor portfolio tuned on the tuning suite; geometric means (95 % interval)")
    for name, m in summaries.items():
        r = m["ratios"]
        cells = [f"{key.removeprefix('adaptive_vs_')} {_g(r[key])}"
                 for key in ("adaptive_vs_fixed", "adaptive_vs_baseline", "adaptive_vs_best")]
        print(f"{name:6s} " + "; ".join(cells) + f"; wins vs fixed "
              f"{r['adaptive_vs_fixed']['wins']}/{len(results)}; worst "
              f"{r['adaptive_vs_fixed']['worst']:.2f}; changes {m['selector']['changes']:.1f}")
    print(json.dumps({k: {n: round(w["ratios"]["adaptive_vs_fixed"], 3)
                          for n, w in m["per_world"].items()} for k, m in summaries.items()}))


def _g(s: dict[str, Any]) -> str:
    return f"{s['geomean']:.2f} ({s['low']:.2f}-{s['high']:.2f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--project", type=Path, required=True)
    parser.add_argument("--worlds", type=int, default=None)
    parser.add_argument("--k", default="1000,3000")
    args = parser.parse_args()
    dev(args.project, args.worlds, [int(k) for k in args.k.split(",")])


if __name__ == "__main__":
    main()
