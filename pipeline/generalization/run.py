"""Baseline, fixed and adaptive on every world of a suite, with the pipeline's own code.

For every world (``pipeline.generalization.suite``), ``score_world``
1. simulates it (``pipeline.sim.simulate.simulate_sequence``) into a scratch MCAP;
2. runs the model's selector and odometry on it (``pipeline.adaptive.run_one``, the ``adaptive``
   stage's code);
3. runs baseline and fixed and scores all three (``pipeline.evaluate.runs.evaluate``, the
   ``evaluate`` stage's code: per-start-frame RTE at L = ``length_m``);
   with ``replicas`` R > 0 every setting runs R times more, its parameters moved by at most
   ``replica_scale`` (``pipeline.evaluate.replicas``);
4. deletes the MCAP (hundreds of MB a world) and keeps the trajectories and the schedule:
   ``<out>/adaptive/<world>/`` and ``<out>/runs/<world>/``.

``run_suite`` does that for every world, ``workers`` worlds at a time (spawned processes), and
writes ``<out>`` atomically.
"""

from __future__ import annotations

import logging
import math
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pipeline.evaluate.result import SETTINGS
from pipeline.generalization.suite import GeneralizeSection, SuiteWorld, suite_worlds
from pipeline.selection import SelectionSettings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WorldScore:
    """One world's result: mean per-start-frame RTE [%] of every setting, overall and per
    environment label, the adaptive run's parameter changes and the wall time [s]; with
    replicas (``pipeline.evaluate.replicas``) the RTE [%] of every replica run of every
    setting (NaN: the odometry failed)."""

    name: str
    segments: tuple[str, ...]
    sensor: str
    frames: int
    seed: int
    rte_pct: dict[str, float]
    rte_pct_per_label: dict[str, dict[str, float]]
    parameter_changes: int
    wall_time_s: float
    replicas_rte_pct: dict[str, list[float]] = field(default_factory=dict)

    @property
    def best_fixed_setting(self) -> str:
        """The better of baseline and fixed on this world."""
        return min(("baseline", "fixed"), key=lambda s: self.rte_pct[s])

    def ratios(self) -> dict[str, float]:
        """adaptive / baseline, adaptive / fixed and adaptive / min(baseline, fixed)."""
        return _ratios(self.rte_pct)

    def runs(self, setting: str) -> list[float]:
        """RTE [%] of the nominal run and of every replica of ``setting``."""
        return [self.rte_pct[setting], *self.replicas_rte_pct.get(setting, [])]

    def replica_medians(self) -> dict[str, float]:
        """Per setting, the median RTE [%] over its nominal and replica runs (failed left out)."""
        return {s: _nanmedian(self.runs(s)) for s in self.rte_pct}

    def replica_ratios(self) -> dict[str, float]:
        """The three ratios of the settings' medians over their runs: what one run says with
        the parameters' chaos averaged out."""
        return _ratios(self.replica_medians())

    def to_json(self) -> dict[str, Any]:
        out = {**asdict(self), "segments": list(self.segments), "ratio": self.ratios()}
        if self.replicas_rte_pct:
            out["replica_ratio"] = self.replica_ratios()
        return out


def _ratios(rte_pct: dict[str, float]) -> dict[str, float]:
    a, b, f = (rte_pct[s] for s in ("adaptive", "baseline", "fixed"))
    return {"adaptive_vs_baseline": _ratio(a, b), "adaptive_vs_fixed": _ratio(a, f),
            "adaptive_vs_best": _ratio(a, min(b, f))}


def _nanmedian(values: list[float]) -> float:
    ok = [v for v in values if math.isfinite(v)]
    return float(statistics.median(ok)) if ok else math.nan


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 and math.isfinite(a) and math.isfinite(b) else math.nan


@dataclass(frozen=True)
class SuiteInputs:
    """What every world is run with: the artifact, the joint study's output (its stored
    parameter space gives the baseline) and best parameters (and their algorithm), the
    adapter's untuned options, L [m], replicas per setting and their relative scale, the
    selector's runtime settings (params ``select``)."""

    model_dir: Path
    fixed_dir: Path
    algorithm: str
    fixed_params: dict[str, float]
    adapter_options: dict[str, Any]
    length_m: float
    replicas: int = 0
    replica_scale: float = 0.005
    selection: SelectionSettings = field(default_factory=SelectionSettings)


def run_suite(section: GeneralizeSection, inputs: SuiteInputs, out_dir: Path) -> list[WorldScore]:
    """Score every world of ``section.suite`` (module docstring); ``out_dir`` is written
    atomically (a failure leaves an existing one untouched)."""
    from pipeline.io_utils import atomic_dir

    worlds = suite_worlds(section)
    log.info("suite %s: %d worlds (%d frames), %d workers", section.suite, len(worlds),
             sum(w.spec.frames for w in worlds), section.workers)
    from pipeline.executor import map_in_processes  # spawned workers that end with us

    with atomic_dir(out_dir) as tmp:
        return map_in_processes(score_world, [(w, inputs, tmp) for w in worlds], section.workers,
                                on_done=lambda i, score: _logged(score, i, len(worlds)))


def _logged(score: WorldScore, i: int, n: int) -> WorldScore:
    r = score.rte_pct
    log.info("[%d/%d] %s (%s, %s): baseline %.3f %%, fixed %.3f %%, adaptive %.3f %% "
             "(x%.2f of the better), %.0f s", i + 1, n, score.name, "-".join(score.segments),
             score.sensor, r["baseline"], r["fixed"], r["adaptive"],
             score.ratios()["adaptive_vs_best"], score.wall_time_s)
    return score


def score_world(world: SuiteWorld, inputs: SuiteInputs, out_dir: Path) -> WorldScore:
    """Simulate ``world``, run adaptive, baseline and fixed, score them (module docstring)."""
    from pipeline.adaptive import loaded_model, run_one
    from pipeline.evaluate.runs import evaluate
    from pipeline.evaluate.section import EvaluateSection
    from pipeline.io_utils import output_folder
    from pipeline.sim.simulate import simulate_sequence

    t0 = time.perf_counter()
    scratch = out_dir / "worlds"
    output_folder(scratch)
    path = scratch / f"{world.name}.mcap"
    try:
        simulate_sequence(world.spec, path, name=world.name)
        run = run_one(loaded_model(inputs.model_dir), path, out_dir / "adaptive" / world.name,
                      inputs.adapter_options, selection=inputs.selection)
        settings = EvaluateSection(length_m=inputs.length_m, replicas=inputs.replicas,
                                   replica_scale=inputs.replica_scale)
        ev = evaluate([path], inputs.algorithm, inputs.fixed_params, out_dir / "adaptive",
                      out_dir / "runs", settings, inputs.adapter_options, inputs.fixed_dir)
    finally:
        path.unlink(missing_ok=True)
    scores = {s: ev.score(s, world.name) for s in SETTINGS}
    return WorldScore(
        world.name, world.spec.segments, world.spec.sensor, world.spec.frames, world.spec.seed,
        {s: x.rte_pct for s, x in scores.items()}, {s: x.per_label() for s, x in scores.items()},
        run.changes, time.perf_counter() - t0,
        {s: x.replica_rte_pct for s, x in scores.items()} if inputs.replicas else {})
