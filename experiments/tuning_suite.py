"""The portfolio tuned on a tuning suite of the suites' own kind, one model per sensor (issue 29;
docs/results/selector-dev.md, "The portfolio on a tuning suite").

Not a `make bench` module (hours). The headroom split (experiments/headroom_controls.py) found
the in-distribution headroom per environment *and sensor* among long mixed worlds, while the
portfolio's 350-frame single-environment training sequences do not carry it over. This study
tunes the portfolio on worlds drawn exactly as the in-distribution suites draw theirs, from a
seed root of their own (``TUNE_ROOT``, committed before anything ran on it), and keys the choice
on the sensor: a deployment knows its sensor, so each sensor gets its own model.

``python experiments/tuning_suite.py simulate --project P --worlds N``
    simulates tuning worlds 0..N-1 (``id_tune_<i>``, the ID draw of P/params.yaml with
    ``TUNE_ROOT``) into P/data/tune/ with an index (all of them ``train``), and per sensor a
    folder P/data/tune_<sensor>/ of links with its own index.
``python experiments/tuning_suite.py dev --project P [--worlds N] [--k 350,1000]``
    after the descriptors, portfolio and rte stages ran per sensor (P/results/<sensor>.duckdb),
    fits per sensor and k the portfolio surrogate into P/dev/models/, runs the ID dev suite's
    worlds of each sensor with that sensor's models (baseline, fixed and every k on every
    replica, ``pipeline.verdict.runs.run_suite``), writes P/dev/tune_<sensor>/ and
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

TUNE_ROOT = 45453
"""The tuning suite's seed root: drawn (secrets.randbelow) and committed before any world of it
was simulated. It differs from every suite's root in verdict/params.yaml."""

PORTFOLIO: dict[str, Any] = {"rows": "portfolio", "n_sobol": 0, "w_x": 1000.0}
"""As experiments/verdict_dev.py: the members as the only candidates, kept apart."""


def tuning_worlds(project: Path, n: int) -> list[Any]:
    """The first ``n`` worlds of the tuning suite (the ID draw with ``TUNE_ROOT``)."""
    from pipeline.verdict.report import load_settings
    from pipeline.verdict.worlds import check_generator, world_of

    section, settings = load_settings(project / "params.yaml")
    check_generator(section)
    draw = section.suites.id.model_copy(update={"seed_roots": {"tune": TUNE_ROOT}})
    return [world_of(draw, "id", "tune", i, settings.template) for i in range(n)]


def simulate(project: Path, n: int, workers: int) -> None:
    """Tuning worlds 0..n-1 into P/data/tune/ and the per-sensor folders of links."""
    from pipeline.sequence_index import write_index
    from pipeline.sim.dataset import simulate_all
    from pipeline.sim.simulate import simulate_sequence

    worlds = tuning_worlds(project, n)
    out = project / "data" / "tune"
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(w.spec, out / f"{w.name}.mcap", w.name, False) for w in worlds
            if not (out / f"{w.name}.mcap").is_file()]
    simulate_all(simulate_sequence, jobs, [j[1] for j in jobs], workers, True)
    write_index(out, {"train": [w.name for w in worlds], "validation": []})
    for sensor in sorted({w.spec.sensor for w in worlds}):
        folder = project / "data" / f"tune_{sensor}"
        folder.mkdir(exist_ok=True)
        names = [w.name for w in worlds if w.spec.sensor == sensor]
        for name in names:
            link = folder / f"{name}.mcap"
            if not link.is_symlink():
                link.symlink_to(Path("..") / "tune" / f"{name}.mcap")
        write_index(folder, {"train": names, "validation": []})
    for w in worlds:
        print(f"{w.name}: {w.description}")


def sensor_model(project: Path, sensor: str, k: int) -> Path:
    """The portfolio surrogate with ``k`` neighbours fitted on ``sensor``'s tuning worlds."""
    from pipeline.config import load_section
    from pipeline.descriptors.dataset import DescriptorsSection
    from pipeline.surrogates.fit import ModelInputs, build_model
    from pipeline.surrogates.section import SurrogateSection
    from pipeline.tuning.table import read_space

    out = project / "dev" / "models" / f"tune_{sensor}_k{k}"
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
    """The ID dev suite, each sensor's worlds with that sensor's models; print and write."""
    from pipeline.report.outputs import write_json
    from pipeline.verdict.report import load_settings, suite_inputs
    from pipeline.verdict.runs import AdaptiveSetting, read_results, run_suite
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
    results = []
    for sensor in sorted({w.spec.sensor for w in worlds}):
        adaptive = {f"adaptive:k{k}": AdaptiveSetting(sensor_model(project, sensor, k), selection)
                    for k in ks}
        out = project / "dev" / f"tune_{sensor}"
        mine = [w for w in worlds if w.spec.sensor == sensor]
        if not out.is_dir():
            run_suite(mine, dataclasses.replace(inputs, adaptive=adaptive), out, section.workers)
        results += read_results(out)
    results.sort(key=lambda r: r.name)
    header = {"family": "id", "suite": "dev", "seed_root": section.root("id"),
              "tuning_root": TUNE_ROOT, "replicas": section.replicas, "fixed_study": study}
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
    parser.add_argument("step", choices=["simulate", "dev"])
    parser.add_argument("--project", type=Path, required=True)
    parser.add_argument("--worlds", type=int, default=None)
    parser.add_argument("--k", default="350,1000")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.step == "simulate":
        simulate(args.project, args.worlds or 24, args.workers)
    else:
        dev(args.project, args.worlds, [int(k) for k in args.k.split(",")])


if __name__ == "__main__":
    main()
