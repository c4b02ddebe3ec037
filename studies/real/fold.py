"""One fold of the real-data study for one algorithm (``run_fold``): it reads like its table of
contents.

1. The fixed set: a joint study over the fold's training units (``fixed``: 64 trials,
   warm-started from the units' own studies, pruned), from the training units' studies only:
   its best ok trial, where a unit the trial failed on counts at the penalty (real/params.yaml's
   ``fixed.failures: sequence``); the defaults where no trial is ok.
2. The environment: the PCA of the descriptors fitted on the training units' frames only.
3. The model: the results database of the training units' studies and the joint study, the
   surrogate fitted on it with the k its cross-validation over the training units chooses
   (``choose_k``; the default k with a single training unit).
4. The in-sample best of every test run: the best set of a study on the run's test units
   themselves (the unit's own study where the run is one unit, else a joint study over them):
   the optimistic end of what fixed parameters can do there, reported as a bound, never a
   choice.
5. The suite: baseline, fixed, adaptive and the in-sample best on every test unit, each on the
   nominal parameters and ``replicas`` more (``studies.suites.runner``), a failed run at the
   trials' penalty.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.tuning.section import TrialsSection
from studies.real.folds import Fold

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FoldPaths:
    """Inputs and outputs of one (fold, algorithm)."""

    units: Path  # data/units: every unit's MCAP and index.json
    descriptors: Path  # data/descriptors.parquet: every unit's frames
    studies: Path  # results/<algorithm>/units: every unit's own study
    out: Path  # results/<algorithm>/folds/<fold>: joint study, pca, db, model, suite


@dataclass(frozen=True)
class FoldSettings:
    """What a fold runs with: the algorithm's per-unit study settings, the joint study's
    (``fixed`` over ``trials``) and its warm start, the descriptors' and the surrogate's
    sections, the selector's settings, the k candidates, the replicas, the seed, the workers
    and the fold whose trajectories the docs draw."""

    trials: TrialsSection
    joint: TrialsSection
    warm_start: int
    descriptors: Any
    surrogate: Any
    selection: Any
    candidates_k: tuple[int, ...]
    replicas: int
    replica_scale: float
    seed: int
    workers: int
    plot_fold: str


def run_fold(fold: Fold, paths: FoldPaths, settings: FoldSettings) -> list[Any]:
    """The fold (module docstring); returns the suite's results."""
    paths.out.mkdir(parents=True, exist_ok=True)
    train = [paths.units / f"{u}.mcap" for u in fold.train]
    fixed_dir = joint_study(train, paths.studies, paths.out / "fixed", settings)
    pca_dir, environment = fold_environment(fold, paths)
    model = fold_model(fold, paths, fixed_dir, pca_dir, environment, settings)
    in_sample = {unit: params for run, units in fold.test.items()
                 for unit, params in in_sample_best(run, units, paths, settings).items()}
    return fold_suite(fold, paths, fixed_dir, model, in_sample, settings)


def joint_study(train: Sequence[Path], studies: Path, out: Path,
                settings: FoldSettings) -> Path:
    """The joint study over ``train``, warm-started from their own studies in ``studies``."""
    from pipeline.tuning.smbo import run_trials, study_adapter
    from pipeline.tuning.warm_start import warm_start_params

    space = study_adapter(settings.joint).space
    first = (warm_start_params(studies, settings.joint.algorithm, space, settings.warm_start,
                               sequences=[p.stem for p in train])
             if settings.warm_start else [])
    run_trials(train, out, settings.joint, settings.seed, joint=True, warm_start=first)
    return out


def fold_environment(fold: Fold, paths: FoldPaths) -> tuple[Path, Path]:
    """The fold's PCA (fitted on its training units' frames only) and every unit's
    environment E under it: (pca folder, environment Parquet), written under ``paths.out``."""
    import numpy as np
    import pyarrow.parquet as pq

    from pipeline.descriptors import descriptor_from_json
    from pipeline.descriptors.dataset import DescriptorSet, write_descriptor_set
    from pipeline.pca import fit_pca

    table = pq.read_table(paths.descriptors)
    meta = json.loads(table.schema.metadata[b"adaptune.descriptor"])
    names = np.array(table.column("sequence").to_pylist())
    values = np.stack([table.column(c).to_numpy() for c in table.column_names
                       if c.startswith("d")], axis=1).astype(np.float32)
    dim = _pca_dim(paths.descriptors)
    pca = fit_pca(values[np.isin(names, fold.train)], dim, list(fold.train))
    pca.descriptor = descriptor_from_json(meta).to_json()
    ds = DescriptorSet(names, table.column("frame").to_numpy().astype(np.int32),
                       table.column("stamp_ns").to_numpy().astype(np.int64), values, pca)
    out_desc, environment, pca_dir = (paths.out / "descriptors.parquet",
                                      paths.out / "environment.parquet", paths.out / "pca")
    write_descriptor_set(ds, out_desc, environment, pca_dir)
    return pca_dir, environment


def _pca_dim(descriptors: Path) -> int:
    """The PCA dimension of the all-units PCA the descriptors stage wrote beside them
    (``pca/pca.json``)."""
    from pipeline.pca import Pca

    return int(Pca.load(descriptors.parent / "pca").components.shape[0])


def fold_model(fold: Fold, paths: FoldPaths, fixed_dir: Path | None, pca_dir: Path,
               environment: Path, settings: FoldSettings) -> Path:
    """The results database of the fold's training units (and its joint study, where it has
    one) and the surrogate fitted on it with the k its cross-validation chooses; returns the
    artifact's folder."""
    from pipeline.database.store import build_database
    from pipeline.metrics.section import DevkitSection
    from pipeline.surrogates.fit import ModelInputs, build_model
    from pipeline.tuning.table import read_adapter_options, read_space

    db = paths.out / "results.duckdb"
    studies = {"trials": paths.studies, **({} if fixed_dir is None else {"fixed": fixed_dir})}
    build_database(db, paths.units, studies,
                   settings.trials.length_m, DevkitSection.model_validate({}),
                   paths.out / "descriptors.parquet", environment, sequences=fold.train)
    algorithm = settings.trials.algorithm
    section = choose_k(db, pca_dir, fold, paths, settings)
    out = paths.out / "model"
    build_model(ModelInputs(db, pca_dir), out, section, settings.descriptors,
                lambda name: read_space(paths.studies, name), algorithm,
                lambda name: read_adapter_options(paths.studies, name))
    return out


NO_CROSS_VALIDATION = "the default: no cross-validation (fewer than two training units with a "\
    "finished trial)"
"""``choice.json``'s ``chosen_by`` where the fold's k is the surrogate section's own."""


def choose_k(db: Path, pca_dir: Path, fold: Fold, paths: FoldPaths,
             settings: FoldSettings) -> Any:
    """The surrogate section with the k of ``settings.candidates_k`` whose leave-one-unit-out
    cross-validation over the fold's training units has the least regret (the smallest k of
    a tie); the section's own k where no cross-validation gave a regret (a single training
    unit, or but one with a finished trial). Written to ``<out>/choice.json``."""
    from pipeline.pca import Pca
    from pipeline.surrogates.fit import fit_surrogate
    from pipeline.surrogates.rows import read_training_rows
    from pipeline.tuning.table import read_space

    section = settings.surrogate
    regrets: dict[int, float | None] = {}
    if len(fold.train) > 1:
        Pca.load(pca_dir)
        algorithm = settings.trials.algorithm
        _, space, rows = read_training_rows(db, algorithm,
                                            lambda name: read_space(paths.studies, name),
                                            section.rows)
        for k in settings.candidates_k:
            fitted = fit_surrogate(rows, space, section.model_copy(update={"k": k}))
            regrets[k] = fitted.cv.get("regret_mean")
    scored = {k: r for k, r in regrets.items() if r is not None}
    k = min(scored, key=lambda k: (scored[k], k)) if scored else section.k
    (paths.out / "choice.json").write_text(json.dumps(
        {"k": k, "regret_mean": regrets, "training_units": len(fold.train),
         "chosen_by": "cross-validation" if scored else NO_CROSS_VALIDATION},
        indent=2) + "\n")
    return section.model_copy(update={"k": k})


def in_sample_best(run: str, units: Sequence[str], paths: FoldPaths,
                   settings: FoldSettings) -> Mapping[str, dict[str, float]]:
    """Per test unit of ``run``, the best set of a study on the run's test units themselves:
    the unit's own study where the run is one unit here, else a joint study over them
    (``<out>/in_sample/<run>``, warm-started from their own studies); the defaults where none
    of its trials finished (``best_or_defaults``; ``<out>/in_sample/<run>.json`` says which)."""
    from pipeline.tuning.layout import JOINT_SEQUENCE

    algorithm = settings.trials.algorithm
    if len(units) == 1:
        study_dir, study = paths.studies, units[0]
    else:
        study_dir, study = paths.out / "in_sample" / run, JOINT_SEQUENCE
        joint_study([paths.units / f"{u}.mcap" for u in units], paths.studies, study_dir,
                    settings)
    best = best_or_defaults(study_dir, study, paths, algorithm,
                            paths.out / "in_sample" / f"{run}.json")
    return {u: best for u in units}


def best_or_defaults(study_dir: Path, study: str, paths: FoldPaths, algorithm: str,
                     record: Path) -> dict[str, float]:
    """The parameters of ``study``'s best finished trial, or the defaults where none of its
    trials finished (no set is known to do better); ``record`` (JSON) says which."""
    from pipeline.io_utils import atomic_write_text
    from pipeline.tuning.table import read_space

    best = study_best(study_dir, algorithm, study)
    source = f"the best finished trial of {study_dir.name}/{study}"
    if best is None:
        log.warning("%s: no trial of %s finished: the defaults stand in", study_dir, study)
        best = read_space(paths.studies, algorithm).defaults()
        source = "the defaults: no trial finished"
    record.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(record, json.dumps({"params": best, "from": source}, indent=2) + "\n")
    return best


def study_best(trials_dir: Path, algorithm: str, study: str) -> dict[str, float] | None:
    """The parameters of ``study``'s best finished trial under ``trials_dir``
    (``pipeline.tuning.layout.best_trial``); None when none finished."""
    from pipeline.tuning.layout import best_trial, read_trials_tables

    rows = [r for r in read_trials_tables(trials_dir).to_pylist()
            if r["sequence"] == study and r["algorithm"] == algorithm]
    tid = best_trial((r["trial"], r["status"], r["objective"]) for r in rows)
    if tid is None:
        return None
    best = next(r for r in rows if r["trial"] == tid)
    return {k: float(v) for k, v in json.loads(best["params_json"]).items()}


def fold_suite(fold: Fold, paths: FoldPaths, fixed_dir: Path, model: Path,
               in_sample: Mapping[str, dict[str, float]], settings: FoldSettings) -> list[Any]:
    """Baseline, fixed (the defaults where no joint trial finished: ``fixed.json`` says which),
    adaptive and the in-sample best on every test unit, with replicas."""
    from pipeline.tuning.layout import JOINT_SEQUENCE
    from pipeline.tuning.table import read_adapter_options, read_space
    from studies.suites.runner import AdaptiveSetting, SuiteInputs, run_suite

    algorithm = settings.trials.algorithm
    fixed = best_or_defaults(fixed_dir, JOINT_SEQUENCE, paths, algorithm,
                             paths.out / "fixed.json")
    space = read_space(paths.studies, algorithm)
    inputs = SuiteInputs(algorithm, space, space.defaults(), fixed,
                         read_adapter_options(paths.studies, algorithm),
                         settings.trials.length_m, settings.replicas, settings.replica_scale,
                         settings.trials.penalty_pct,
                         adaptive={"adaptive": AdaptiveSetting(model, settings.selection)},
                         constant={"in_sample": dict(in_sample)},
                         keep_trajectories=fold.name == settings.plot_fold)
    subjects = [recorded_unit(paths.units / f"{u}.mcap", fold.name) for u in fold.test_units]
    return run_suite(subjects, inputs, paths.out / "suite", settings.workers)


def recorded_unit(path: Path, family: str) -> Any:
    """A unit as the suite runner's recorded run, with its sensor, frames, own L and jump
    limit."""
    from pipeline.sequence import SequenceReader
    from studies.suites.worlds import RecordedRun

    with SequenceReader(path) as reader:
        info = reader.info
        return RecordedRun(path.stem, family, path, info.sensor or "unknown", len(reader),
                           info.length_m, info.jump_limit_m)
