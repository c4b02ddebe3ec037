"""The portfolio tuned on the tuning suite, one model per sensor, on the ID dev suite (issue 29;
docs/results/selector-dev.md, "The portfolio on a tuning suite").

Not a `make bench` module (an hour and more). The headroom split (experiments/headroom_controls.py)
found the in-distribution headroom per environment *and sensor* among long mixed worlds, while
the portfolio's 350-frame single-environment training sequences do not carry it over. This
study tunes the portfolio on the tuning suite (``studies.verdict.tuning``: worlds drawn as the
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
    python experiments/tuning_suite.py --project P --family ood --worlds 12 --k 1000

The last steps fit per sensor and k the portfolio surrogate into P/dev/models/k<k>/<sensor>/
and run the family's dev suite (baseline, fixed and every adaptive setting on every replica;
``studies.suites.runner.run_suite``): ``id``, each world with its sensor's model of every k;
``ood``, whose sensor has no model (so the suite's own rule runs the fixed set, the fixed
column), with each trained sensor's model borrowed (``--lenders``). They write
P/dev/tune_<family>/ and P/dev/tune_<family>.json and print one row per setting.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # verdict_dev's summary row

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


def borrowed(project: Path, k: int, sensor: str, lender: str) -> Path:
    """A model folder whose ``sensor`` model is ``lender``'s (k ``k``): what a sensor kept out
    of training would run if it borrowed a trained sensor's model (a link, nothing refitted)."""
    out = project / "dev" / "models" / f"k{k}_{sensor}_as_{lender}"
    out.mkdir(parents=True, exist_ok=True)
    link = out / sensor
    if not link.is_symlink():
        link.symlink_to(Path("..") / f"k{k}" / lender)
    return out


def dev(project: Path, family: str, n_worlds: int | None, ks: list[int],
        lenders: list[str]) -> None:
    """The family's dev suite, each world with its sensor's model of every k (``id``), or with
    each lender's model (``ood``: the sensor has none; the fixed set is the fixed column);
    print and write."""
    from verdict_dev import summary_row

    from pipeline.report.outputs import write_json
    from studies.verdict.report import load_settings, suite_inputs
    from studies.suites.runner import AdaptiveSetting, run_suite
    from studies.verdict.summary import suite_metrics
    from studies.verdict.worlds import suite_worlds

    section, settings = load_settings(project / "params.yaml")
    draw = section.suites.draw(family)
    if n_worlds is not None:
        draw = draw.model_copy(update={"worlds": n_worlds})
    section = section.model_copy(update={"suite": "dev", "suites": section.suites.model_copy(
        update={family: draw})})
    inputs, study = suite_inputs(None, project / "results" / "fixed", section, settings)
    worlds = suite_worlds(section, family, settings.template)
    selection = settings.selection.replace(refine_iters=0)
    trained = ["hdl32", "hdl64"]
    for k in ks:
        for sensor in trained:
            sensor_model(project, sensor, k)
    if family == "id":
        folders = {f"k{k}": project / "dev" / "models" / f"k{k}" for k in ks}
    else:
        folders = {f"k{k}_as_{lender}": borrowed(project, k, sensor, lender) for k in ks
                   for lender in lenders for sensor in sorted({w.spec.sensor for w in worlds})}
    adaptive = {f"adaptive:{name}": AdaptiveSetting(folder, selection)
                for name, folder in folders.items()}
    results = run_suite(worlds, dataclasses.replace(inputs, adaptive=adaptive),
                        project / "dev" / f"tune_{family}", section.workers)
    header = {"family": family, "suite": "dev", "seed_root": section.root(family),
              "tuning_root": section.tuning.seed_root, "replicas": section.replicas,
              "fixed_study": study}
    summaries = {name: suite_metrics(results, header, section.failure_pct, section.confidence,
                                     section.resamples, section.root(family), f"adaptive:{name}")
                 for name in folders}
    write_json(project / "dev" / f"tune_{family}.json", summaries)
    print(f"{family} dev suite, {len(results)} worlds, {section.replicas + 1} runs a setting, "
          "per-sensor portfolio tuned on the tuning suite; geometric means (95 % interval)")
    for name, m in summaries.items():
        print(summary_row(name, m))
    print(json.dumps({k: {n: round(w["ratios"]["adaptive_vs_fixed"], 3)
                          for n, w in m["per_world"].items()} for k, m in summaries.items()}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--project", type=Path, required=True)
    parser.add_argument("--family", choices=["id", "ood"], default="id")
    parser.add_argument("--worlds", type=int, default=None)
    parser.add_argument("--k", default="1000,3000")
    parser.add_argument("--lenders", default="hdl32,hdl64",
                        help="ood: the trained sensors whose models the unseen sensor borrows")
    args = parser.parse_args()
    dev(args.project, args.family, args.worlds, [int(k) for k in args.k.split(",")],
        args.lenders.split(","))


if __name__ == "__main__":
    main()
