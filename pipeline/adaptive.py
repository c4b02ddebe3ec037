"""Adaptive runs (docs/design.md, "Method", step 5): the model picks parameters, the odometry
uses them.

For every sequence, ``run_adaptive``
1. loads the artifact (``pipeline.runtime.load_model``, checksums verified);
2. computes the parameter schedule from the scans alone (``Selector.schedule``: a selection every
   ``period_s`` from the newest scan, held in between), exactly what the online selector beside a
   live odometry would choose, since x_t depends only on the scans up to t;
3. runs the model's odometry with that schedule (``run_sequence``: parameters change mid-run);
4. writes ``<out>/<sequence>/schedule.parquet``, ``trajectory.parquet`` and ``run.json``
   (frames, selections, number of parameter changes; the wall times of selection and odometry
   go to the stage's record: an output holds nothing a run's speed does, docs/design.md,
   "Same numbers on every machine").
"""

from __future__ import annotations

import functools
import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pipeline.io_utils import atomic_write_text
from pipeline.selection import SelectionSettings

log = logging.getLogger(__name__)


@dataclass
class AdaptiveRun:
    """What one adaptive run produced (``run.json``)."""

    sequence: str
    algorithm: str
    frames: int
    selections: int
    changes: int
    select_s: float
    odometry_s: float

    @property
    def wall_time_s(self) -> float:
        """Selection plus odometry [s]."""
        return self.select_s + self.odometry_s

    def to_json(self) -> dict[str, Any]:
        """``run.json``: what the run did (no wall times)."""
        return {k: v for k, v in asdict(self).items() if k not in ("select_s", "odometry_s")}

    def record(self) -> dict[str, Any]:
        """The run in the stage's record: ``to_json`` and the wall times [s]."""
        return {**asdict(self), "wall_time_s": self.wall_time_s}


def run_adaptive(model_dir: str | Path, sequence_paths: Sequence[str | Path], out_dir: str | Path,
                 adapter_options: Mapping[str, Any] | None = None,
                 time_limit_s: float | None = None, workers: int = 1,
                 selection: SelectionSettings | None = None) -> list[AdaptiveRun]:
    """Schedule and run every sequence with the model of ``model_dir``; see the module docstring.

    adapter_options: untuned settings of the model's adapter (as in the trials); selection: the
    selector's runtime settings (params ``select``; None: their defaults); workers:
    sequences run at a time, in spawned processes (each sequence's run depends on the model and
    the sequence alone, so the outputs are the same for any number).
    Raises ArtifactError for a bad model, InputError for bad sequences, OdometryError when the
    odometry fails (an adaptive run has no penalty to fall back on).
    """
    from pipeline.executor import map_in_processes
    from pipeline.odometry.registry import declared_space
    from pipeline.runtime import load_model

    # a bad artifact fails here, once, before any worker starts
    load_model(model_dir, declared_space=declared_space)
    jobs = [(Path(model_dir), Path(p), Path(out_dir) / Path(p).stem, adapter_options,
             time_limit_s, selection) for p in sequence_paths]
    return map_in_processes(_run_loaded, jobs, workers)


def _run_loaded(model_dir: Path, sequence_path: Path, out_dir: Path,
                adapter_options: Mapping[str, Any] | None, time_limit_s: float | None,
                selection: SelectionSettings | None) -> AdaptiveRun:
    """``run_one`` with the artifact at ``model_dir``, loaded once per process."""
    return run_one(loaded_model(model_dir), sequence_path, out_dir, adapter_options, time_limit_s,
                   selection)


@functools.lru_cache(maxsize=2)
def loaded_model(model_dir: Path) -> Any:
    """The verified artifact of ``model_dir``, loaded once per process (worker processes run
    many sequences or worlds with one model)."""
    from pipeline.runtime import load_model

    return load_model(model_dir)


def run_one(model: Any, sequence_path: Path, out_dir: Path,
            adapter_options: Mapping[str, Any] | None = None,
            time_limit_s: float | None = None,
            selection: SelectionSettings | None = None) -> AdaptiveRun:
    """One sequence: schedule, run, write (module docstring)."""
    from pipeline.odometry import run_sequence
    from pipeline.odometry.registry import build_adapter
    from pipeline.runtime import Selector
    from pipeline.sequence import SequenceReader
    from pipeline.trajectory import write_trajectory

    selector = Selector(model, selection)
    t0 = time.perf_counter()
    with SequenceReader(sequence_path) as reader:
        schedule = selector.schedule(reader)
        frames = len(reader)
    select_s = time.perf_counter() - t0
    adapter = build_adapter(model.algorithm, adapter_options, model.space)  # as trained
    t0 = time.perf_counter()
    traj = run_sequence(adapter, sequence_path, schedule, time_limit_s=time_limit_s)
    odometry_s = time.perf_counter() - t0
    run = AdaptiveRun(sequence_path.stem, model.algorithm, frames, selector.selections,
                      schedule.n_changes, select_s, odometry_s)
    schedule.write(out_dir / "schedule.parquet")
    write_trajectory(out_dir / "trajectory.parquet", traj,  # paths relative to the file
                     {"setting": "adaptive", "algorithm": model.algorithm,
                      "sequence": os.path.relpath(sequence_path, out_dir),
                      "model": os.path.relpath(model.path, out_dir)})
    atomic_write_text(out_dir / "run.json", json.dumps(run.to_json(), indent=2) + "\n")
    log.info("%s: %d frames, %d parameter changes, selection %.1f s, odometry %.1f s",
             run.sequence, frames, run.changes, select_s, odometry_s)
    return run

