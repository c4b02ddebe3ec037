"""Trials output folders as an Optuna storage, for optuna-dashboard (docs/usage.md, "Trials in
optuna-dashboard").

Every study of a trials output folder (``pipeline.tuning.layout``: the per-sequence studies of
``results/trials``, the joint study of ``results/fixed``) becomes an Optuna study named
``<folder>/<algorithm>/<sequence>`` (``trials/gicp/04``, ``fixed/gicp/__joint__``), minimising,
filled through Optuna's own API (``optuna.trial.create_trial`` and ``Study.add_trials``): one
Optuna trial per trial of the trials table, in trial order, with

- its parameters and their distributions from the parameter space stored with the table
  (``pipeline.tuning.table.read_study``): ``FloatDistribution(low, high, log)`` for a float
  parameter, ``IntDistribution(low, high, log)`` for an int one;
- its state: ok -> COMPLETE (value: the objective, mean RTE [%]), pruned -> PRUNED (value: the
  running RTE where it stopped, also its intermediate value at the frames it ran), failed ->
  FAIL (no value: Optuna keeps none for a failed trial; the penalty is the user attribute
  ``penalty_pct``, the error ``error``); a lost trial (the machinery failed, never scored) is
  left out and counted (``ExportedStudy.lost``);
- user attributes ``trial`` (adaptune's trial id: Optuna numbers the trials it holds
  0, 1, ... so they differ once a lost trial is left out), ``frames`` (the frames its stored
  trajectories hold over the study's sequences: all of them for a complete trial, those it ran
  for a pruned one, 0 for a failed one, whose trajectories are not kept) and ``seed``. A trials
  table keeps no time (the same numbers on every run; a study's wall time is in its stage's
  record), so the trials start and end at the export; a table written before schema 1.1 gives
  its trials' ``wall_time_s``, and their start is their end minus it.

The storage is a new SQLite file written atomically (``pipeline.io_utils.atomic_path``): an
existing one is replaced whole. optuna is imported inside the function.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import InputError, OutputError
from pipeline.io_utils import atomic_path, refuse_input_as_output
from pipeline.odometry.base import ParameterSpace, ParamSpec
from pipeline.tuning.layout import trajectory_path, trials_files
from pipeline.tuning.table import read_study

STATES = {"ok": "COMPLETE", "pruned": "PRUNED", "failed": "FAIL"}
"""Trials table status -> Optuna TrialState name; a lost trial has none (left out)."""


@dataclass(frozen=True)
class ExportedStudy:
    """One study written: its Optuna name, the trials exported by Optuna state name, and the
    lost trials left out."""

    name: str
    states: dict[str, int]
    lost: int

    @property
    def trials(self) -> int:
        return sum(self.states.values())


def export_optuna(folders: Sequence[str | Path], out: str | Path) -> list[ExportedStudy]:
    """Write every study of the trials output ``folders`` into a new Optuna SQLite storage
    ``out`` (module docstring); InputError when a folder holds no trials table, a table has no
    stored parameter space, or two folders give one study name."""
    import optuna

    studies = _studies(folders)
    refuse_input_as_output(out, [path for _, _, path in studies])
    if Path(out).exists() and not Path(out).is_file():
        raise OutputError(f"{out}: an Optuna SQLite storage is a regular file, this is not one")
    exported = []
    verbosity = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)  # no "A new study created" lines
    try:
        with atomic_path(out) as tmp:
            storage = optuna.storages.RDBStorage(f"sqlite:///{tmp}")
            try:
                for name, folder, path in studies:
                    exported.append(_export_study(storage, name, folder, path))
            finally:
                storage.engine.dispose()
    finally:
        optuna.logging.set_verbosity(verbosity)
    return exported


def _studies(folders: Sequence[str | Path]) -> list[tuple[str, Path, Path]]:
    """(Optuna study name, folder, trials table) of every study of ``folders``."""
    found: dict[str, tuple[str, Path, Path]] = {}
    for folder in map(Path, folders):
        if not folder.is_dir():
            raise InputError(f"{folder}: no such trials folder")
        tables = trials_files(folder)
        if not tables:
            raise InputError(f"{folder}: no trials table (expected trials/algorithm=<A>/"
                             "sequence=<S>/trials.parquet, an `adaptune trials` output folder)")
        for algorithm, sequence, path in tables:
            name = f"{folder.resolve().name}/{algorithm}/{sequence}"
            if name in found:
                raise InputError(f"{path}: its study name {name!r} is also "
                                 f"{found[name][2]}'s; export the two folders separately")
            found[name] = (name, folder, path)
    return list(found.values())


def _export_study(storage: Any, name: str, folder: Path, path: Path) -> ExportedStudy:
    """One trials table as the Optuna study ``name`` in ``storage``."""
    import optuna
    import pyarrow.parquet as pq

    study_info = read_study(path)
    if study_info is None or not isinstance(study_info.get("space"), list):
        raise InputError(f"{path}: no parameter space stored with it (written by an older "
                         "adaptune); run the trials again")
    space = ParameterSpace.from_json(study_info["space"], str(path))
    sequences = [str(s["name"]) for s in study_info.get("sequences", []) if isinstance(s, dict)]
    algorithm = path.parent.parent.name.removeprefix("algorithm=")
    distributions = {s.name: _distribution(s) for s in space.specs}
    study = optuna.create_study(storage=storage, study_name=name, direction="minimize")
    for key, value in (("algorithm", algorithm), ("length_m", study_info.get("length_m")),
                       ("penalty_pct", study_info.get("penalty_pct")),
                       ("sequences", sequences), ("trials_table", str(path.resolve()))):
        study.set_user_attr(key, value)
    for key, attr in (("length_m", "sequence_lengths_m"),
                      ("jump_limit_m", "sequence_jump_limits_m")):  # their own, over the study's
        own = {str(s["name"]): s[key] for s in study_info.get("sequences", [])
               if isinstance(s, dict) and key in s}
        if own:
            study.set_user_attr(attr, own)
    rows = pq.read_table(path).to_pylist()
    trials: list[Any] = []
    states: dict[str, int] = {}
    lost = 0
    for row in rows:
        if row["status"] not in STATES:
            lost += 1
            continue
        frames = _frames(folder, algorithm, sequences, int(row["trial"]))
        trials.append(_trial(row, space, distributions, frames))
        states[STATES[row["status"]]] = states.get(STATES[row["status"]], 0) + 1
    study.add_trials(trials)
    return ExportedStudy(name, states, lost)


def _distribution(spec: ParamSpec) -> Any:
    """The Optuna distribution of one parameter of the space."""
    import optuna

    if spec.kind == "int":
        return optuna.distributions.IntDistribution(int(spec.low), int(spec.high), log=spec.log)
    return optuna.distributions.FloatDistribution(spec.low, spec.high, log=spec.log)


def _trial(row: dict[str, Any], space: ParameterSpace, distributions: dict[str, Any],
           frames: int) -> Any:
    """The Optuna FrozenTrial of one row of a trials table (module docstring)."""
    import optuna

    state = getattr(optuna.trial.TrialState, STATES[row["status"]])
    params = {s.name: round(row[f"p_{s.name}"]) if s.kind == "int"
              else float(row[f"p_{s.name}"]) for s in space.specs}
    attrs: dict[str, Any] = {"trial": int(row["trial"]), "frames": frames,
                             "seed": int(row["seed"])}
    wall_s = row.get("wall_time_s")  # a table of schema 1.0 (LEGACY_TRIALS_COLUMNS)
    if wall_s is not None and math.isfinite(wall_s):
        attrs["wall_time_s"] = float(wall_s)
    if row["error"]:
        attrs["error"] = row["error"]
    value, intermediate = None, None
    if row["status"] == "failed":
        attrs["penalty_pct"] = float(row["objective"])
    else:
        value = float(row["objective"])
        if row["status"] == "pruned":  # its running RTE where it stopped (NaN: no segment)
            value = value if math.isfinite(value) else None
            intermediate = None if value is None else {frames: value}
    trial = optuna.trial.create_trial(state=state, value=value, params=params,
                                      distributions=distributions, user_attrs=attrs,
                                      intermediate_values=intermediate)
    if "wall_time_s" in attrs:
        end = trial.datetime_complete or datetime.datetime.now()
        trial.datetime_start = end - datetime.timedelta(seconds=max(attrs["wall_time_s"], 0.0))
    return trial


def _frames(folder: Path, algorithm: str, sequences: list[str], trial: int) -> int:
    """Frames of ``trial``'s stored trajectories over ``sequences`` (Parquet footers only)."""
    import pyarrow.parquet as pq

    total = 0
    for sequence in sequences:
        path = trajectory_path(folder, algorithm, sequence, trial)
        if path.is_file():
            total += pq.ParquetFile(path).metadata.num_rows
    return total

