"""The one suite runner: settings over a suite of subjects, each setting on every replica
(docs/design.md, "The suite runner").

A subject is a simulated world or a recorded run (``studies.suites.worlds``); the settings are
constant parameter sets (the baseline, the fixed set, any other: ``SuiteInputs.constant``) and
adaptive ones (a model and its selector). For every subject ``score_world``
1. loads it into memory once (``LoadedWorld``);
2. computes the schedule of every adaptive setting (the model's selector with that setting's
   ``select`` settings: ``adaptive`` in the stage, more in a dev study of selector variants);
   with one model per sensor, the world's sensor's; a sensor without one (kept out of
   training) borrows the model of ``verdict.borrow_model``, or runs the fixed set (its runs
   are then fixed's);
3. runs baseline (the frozen defaults), fixed (the joint study's best) and every adaptive
   schedule on the nominal parameters and on replicas 1..R;
4. writes ``<out>/<world>/``: ``rte.parquet`` (frame, label, one column ``<setting>/<r>`` per
   run: per-start-frame RTE [%], NaN where no sub-trajectory starts), ``world.json`` (the
   world, the runs that failed, what each selector did, the wall time) and
   ``<setting>.schedule.parquet`` per adaptive setting.

``run_suite`` does that for every world, ``workers`` worlds at a time (spawned processes), and
writes ``<out>`` atomically; ``read_results`` reads it back (the summary and the headroom study
start from it).
"""

from __future__ import annotations

import itertools
import json
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.artifact import MANIFEST_NAME
from pipeline.errors import InputError
from pipeline.selection import SelectionSettings
from studies.suites.statistics import median_over_runs
from studies.suites.worlds import Subject

log = logging.getLogger(__name__)
PROGRESS = logging.getLogger("pipeline.progress")  # shown at any CLI verbosity (stages/cli.py)

F64 = NDArray[np.float64]
FIXED_SETTINGS = ("baseline", "fixed")


@dataclass(frozen=True)
class AdaptiveSetting:
    """An adaptive setting: the artifact, or a folder of one artifact per sensor (named for
    it: the coverage model's portfolio, ``studies.verdict.tuning``), the selector's runtime
    settings it runs with, and the sensor whose model a sensor without one borrows."""

    model_dir: Path
    selection: SelectionSettings = field(default_factory=SelectionSettings)
    borrow: str | None = None

    def model_for(self, sensor: str) -> Path | None:
        """The artifact a world of ``sensor`` runs: ``model_dir`` when it is one artifact, else
        its subfolder ``sensor``, else (a sensor kept out of training) the subfolder of the
        sensor it borrows from (``borrow``); None when there is none: the world runs the fixed
        set."""
        if (self.model_dir / MANIFEST_NAME).is_file():
            return self.model_dir
        for name in (sensor, self.borrow):
            if name is not None and (self.model_dir / name / MANIFEST_NAME).is_file():
                return self.model_dir / name
        return None

    def check(self) -> None:
        """InputError unless ``model_dir`` is an artifact or holds one for some sensor."""
        folder = self.model_dir
        if (folder / MANIFEST_NAME).is_file() or any(folder.glob(f"*/{MANIFEST_NAME}")):
            return
        raise InputError(f"{folder}: neither an artifact ({MANIFEST_NAME}) nor a folder of one "
                         f"artifact per sensor (<sensor>/{MANIFEST_NAME})")


Params = dict[str, float]


@dataclass(frozen=True)
class SuiteInputs:
    """What every subject is run with: the algorithm and the parameter space the studies
    searched, the baseline and fixed parameters, the adapter's untuned options, L [m] (a
    subject's own ``length_m`` overrides it), the replicas, the failure penalty [%] (None: a
    failed run has no score), the adaptive settings to run by name (the stage runs one,
    ``adaptive``; a dev study of selector variants several; the headroom study none) and more
    constant settings by name (``constant``: one parameter set, or one per subject or sensor,
    by the subject's name first, then its sensor, the fixed set for a subject with neither)."""

    algorithm: str
    space: Any
    baseline: Params
    fixed: Params
    adapter_options: dict[str, Any]
    length_m: float
    replicas: int
    replica_scale: float
    penalty_pct: float | None
    adaptive: dict[str, AdaptiveSetting] = field(default_factory=dict)
    constant: dict[str, Params | dict[str, Params]] = field(default_factory=dict)
    keep_trajectories: bool = False
    """Write every setting's nominal trajectory beside the subject's runs (a figure's)."""

    def constants_for(self, subject: str, sensor: str) -> dict[str, Params]:
        """Every constant setting the subject ``subject`` (of ``sensor``) runs, by name:
        baseline, fixed and ``constant``'s (one per subject or sensor resolved for it)."""
        out = {"baseline": self.baseline, "fixed": self.fixed}
        for name, value in self.constant.items():
            if all(isinstance(v, Mapping) for v in value.values()):  # per subject or sensor
                chosen = value.get(subject, value.get(sensor, self.fixed))
                out[name] = dict(chosen)  # type: ignore[arg-type]
            else:
                out[name] = dict(value)  # type: ignore[arg-type]
        return out


@dataclass
class WorldResult:
    """One world's runs: per setting, the per-start-frame RTE (R + 1, N) [%] of its nominal run
    and replicas, which of them failed, and per adaptive setting what its selector did."""

    name: str
    family: str
    segments: tuple[str, ...]
    sensor: str
    frames: int
    seed: int
    labels: list[str]
    t_err_pct: dict[str, F64]
    failed: dict[str, list[bool]]
    selection: dict[str, dict[str, float]]
    wall_time_s: float

    @property
    def settings(self) -> list[str]:
        return list(self.t_err_pct)

    def run_rte(self, setting: str, label: str | None = None) -> F64:
        """Mean RTE [%] of every run of ``setting`` (R + 1,), over the sub-trajectories that
        start in ``label`` (None: all)."""
        t = self.t_err_pct[setting]
        if label is not None:
            t = t[:, np.array(self.labels) == label]
        with np.errstate(invalid="ignore"):
            return np.array([np.nanmean(r) if np.isfinite(r).any() else np.nan for r in t])

    def median(self, setting: str, label: str | None = None) -> float:
        """The world's RTE [%] of ``setting``: the median over its runs."""
        return median_over_runs(self.run_rte(setting, label))

    def ratio(self, setting: str, other: str) -> float:
        """median(setting) / median(other) on this world (``min`` as ``other``: the smaller
        of the baseline's and the fixed set's medians)."""
        den = (min(self.median(s) for s in FIXED_SETTINGS) if other == "min"
               else self.median(other))
        return self.median(setting) / den if den > 0 else float("nan")

    def to_json(self) -> dict[str, Any]:
        """``world.json``: what ran and what the selector did (no wall time: an output holds
        nothing a run's speed does; docs/design.md, "Same numbers on every machine")."""
        return {"name": self.name, "family": self.family, "segments": list(self.segments),
                "sensor": self.sensor, "frames": self.frames, "seed": self.seed,
                "failed": self.failed, "selection": self.selection}


def run_suite(worlds: Sequence[Subject], inputs: SuiteInputs, out_dir: Path,
              workers: int) -> list[WorldResult]:
    """Score every subject (module docstring), the costliest started first; ``out_dir`` is
    written atomically."""
    from pipeline.executor import costliest_first, map_in_processes
    from pipeline.io_utils import atomic_dir

    PROGRESS.info("%d worlds (%d frames), %d replicas, %d workers", len(worlds),
                  sum(w.frames for w in worlds), inputs.replicas, workers)
    t0 = time.monotonic()
    finished = itertools.count(1)
    with atomic_dir(out_dir) as tmp:
        return map_in_processes(
            score_world, [(w, inputs, tmp) for w in worlds], workers,
            on_done=lambda _, r: _world_logged(r, next(finished), len(worlds), t0),
            order=costliest_first([w.cost for w in worlds]))


def _world_logged(result: WorldResult, finished: int, n: int, t0: float) -> WorldResult:
    """A progress line for the ``finished``-th world of ``n`` to finish."""
    m = {s: result.median(s) for s in result.settings}
    PROGRESS.info("[%d/%d] %s (%s, %s, %d frames): %s; %.0f s (%.0f s in all)", finished, n,
                  result.name, "-".join(result.segments), result.sensor, result.frames,
                  ", ".join(f"{s} {v:.3f} %" for s, v in m.items()), result.wall_time_s,
                  time.monotonic() - t0)
    return result


def score_world(world: Subject, inputs: SuiteInputs, out_dir: Path) -> WorldResult:
    """Load ``world``, run every setting on every replica, write and return its runs."""
    t0 = time.perf_counter()
    loaded = load_world(world, inputs)
    from pipeline.adaptive import loaded_model

    nominal: dict[str, Any] = dict(inputs.constants_for(world.name, world.sensor))
    selection, as_fixed = {}, []
    for name, adaptive in inputs.adaptive.items():
        model_dir = adaptive.model_for(world.sensor)
        if model_dir is None:  # no model for this sensor: the fixed set, its runs
            as_fixed.append(name)
            selection[name] = {"changes": 0, "novel_share": 1.0,
                               "edge_share": _edge_share(inputs.fixed, inputs.space)}
            continue
        chosen = loaded.select(loaded_model(model_dir), adaptive.selection)
        nominal[name] = chosen.schedule
        selection[name] = {"changes": chosen.changes, "novel_share": chosen.novel_share,
                           "edge_share": chosen.edge_share}
        chosen.schedule.write(out_dir / world.name / f"{name}.schedule.parquet")
    t_err, failed = {}, {}
    for name, setting in nominal.items():
        runs = [loaded.run_trajectory(setting, r, inputs.replica_scale)
                for r in range(inputs.replicas + 1)]
        t_err[name] = np.stack([t for t, _, _ in runs])
        failed[name] = [f for _, f, _ in runs]
        if inputs.keep_trajectories and runs[0][2] is not None:
            from pipeline.trajectory import write_trajectory

            write_trajectory(out_dir / world.name / f"{name}.trajectory.parquet", runs[0][2],
                             {"setting": name, "sequence": world.name})
    for name in as_fixed:
        t_err[name], failed[name] = t_err["fixed"], failed["fixed"]
    result = WorldResult(world.name, world.family, world.segments, world.sensor,
                         world.frames, world.seed, loaded.labels, t_err, failed,
                         selection, time.perf_counter() - t0)
    write_runs(out_dir / world.name, result)
    return result


def _edge_share(params: Mapping[str, float], space: Any) -> float:
    """``edge_share`` of a constant setting: 1.0 when a parameter is within 1 % of its range's
    width from a bound, else 0.0."""
    from studies.suites.loaded import edge_share

    return edge_share(np.array([[params[n] for n in space.names]]), space.to_json())


def load_world(world: Subject, inputs: SuiteInputs) -> Any:
    """``world`` loaded into memory, the adapter warmed over its scans (``LoadedWorld``), at
    its own L where it has one, with its jump limit."""
    from studies.suites.loaded import LoadedWorld

    scans, labels = world.load()
    length_m = world.length_m or inputs.length_m
    return LoadedWorld(world.name, scans, labels, inputs.algorithm, inputs.adapter_options,
                       inputs.space, length_m, inputs.penalty_pct, world.jump_limit_m)


def write_runs(folder: Path, result: WorldResult) -> None:
    """``rte.parquet`` and ``world.json`` of one world (module docstring)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.io_utils import atomic_path, atomic_write_text

    columns: dict[str, Any] = {"frame": np.arange(result.frames, dtype=np.int32),
                               "label": result.labels}
    for setting, t in result.t_err_pct.items():
        for r, row in enumerate(t):
            columns[f"{setting}/{r}"] = row
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "rte.parquet") as tmp:
        pq.write_table(pa.table(columns), tmp)
    atomic_write_text(folder / "world.json", json.dumps(result.to_json(), indent=2) + "\n")


def read_results(out_dir: Path) -> list[WorldResult]:
    """Every world ``run_suite`` wrote under ``out_dir``, by name."""
    import pyarrow.parquet as pq

    out = []
    for meta_path in sorted(out_dir.glob("*/world.json")):
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        table = pq.read_table(meta_path.parent / "rte.parquet").to_pydict()
        runs: dict[str, list[tuple[int, list[float]]]] = {}
        for column, values in table.items():
            if "/" in column:
                setting, r = column.rsplit("/", 1)
                runs.setdefault(setting, []).append((int(r), values))
        t_err = {s: np.array([v for _, v in sorted(rs)], np.float64) for s, rs in runs.items()}
        out.append(WorldResult(meta["name"], meta["family"], tuple(meta["segments"]),
                               meta["sensor"], int(meta["frames"]), int(meta["seed"]),
                               list(table["label"]), t_err, meta["failed"], meta["selection"],
                               float(meta.get("wall_time_s", "nan"))))
    return out


def world_failures(results: Sequence[WorldResult]) -> Mapping[str, int]:
    """Failed runs per setting over the suite."""
    out: dict[str, int] = {}
    for r in results:
        for s, f in r.failed.items():
            out[s] = out.get(s, 0) + sum(f)
    return out
