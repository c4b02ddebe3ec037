"""The real-data study's steps (the stages of real/dvc.yaml; docs/results/real.md), on the
settings ``studies.real.settings`` reads:

- ``unit_studies``: every unit's own study of an algorithm (``trials.iterations``);
- ``run_folds``: every fold of an algorithm (``studies.real.fold``), its results read back;
- ``deploy_models``: one model per sensor and algorithm from all of that sensor's units;
- the figures: ``studies.real.report``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from studies.real.settings import StudySettings, algorithm_settings


def unit_studies(units_dir: Path, algorithm: str, out: Path, settings: StudySettings) -> list[Any]:
    """Every unit's own study of ``algorithm`` into ``out`` (resumable, as the trials stage)."""
    from pipeline.sequence_index import read_index
    from pipeline.tuning.smbo import run_trials

    paths = read_index(units_dir).paths("train")
    return run_trials(paths, out, algorithm_settings(settings, algorithm), settings.seed)


def fold_settings(settings: StudySettings, algorithm: str) -> Any:
    """A fold's settings for ``algorithm`` (``studies.real.fold.FoldSettings``)."""
    from pipeline.tuning.section import joint_settings
    from studies.real.fold import FoldSettings

    trials = algorithm_settings(settings, algorithm)
    real = settings.real
    return FoldSettings(trials, joint_settings(trials, settings.fixed), settings.fixed.warm_start,
                        settings.descriptors, settings.surrogate, settings.selection,
                        real.candidates_k, real.replicas, real.replica_scale, settings.seed,
                        real.workers, real.plot_fold)


def run_folds(units_dir: Path, descriptors: Path, studies: Path, out: Path,
              settings: StudySettings, algorithm: str) -> dict[str, list[Any]]:
    """Every fold of ``algorithm`` (``studies.real.fold.run_fold``) into ``out/<fold>``;
    returns each fold's suite results."""
    from studies.real.fold import FoldPaths, run_fold
    from studies.real.folds import folds
    from studies.real.units import read_units

    units = read_units(units_dir)
    fs = fold_settings(settings, algorithm)
    return {f.name: run_fold(f, FoldPaths(units_dir, descriptors, studies, out / f.name), fs)
            for f in folds(units, settings.real)}


def deploy_models(units_dir: Path, descriptors: Path, studies: Path, work: Path, out: Path,
                  settings: StudySettings, algorithm: str) -> dict[str, Path]:
    """One model per sensor of ``algorithm``, trained on all of that sensor's units (their own
    studies; no joint study: an unfamiliar scan falls back on the defaults): the fold
    machinery with every unit of the sensor training and none tested, its database and PCA
    in ``work/<sensor>``, the model in ``out/<sensor>/<algorithm>``."""
    from studies.real.fold import FoldPaths, fold_environment, fold_model
    from studies.real.folds import Fold
    from studies.real.units import read_units

    units = read_units(units_dir)
    fs = fold_settings(settings, algorithm)
    models = {}
    for sensor in sorted({r.sensor for r in settings.real.runs}):
        runs = {r.name for r in settings.real.runs if r.sensor == sensor}
        fold = Fold(sensor, "deploy", tuple(u.name for u in units if u.run in runs), {})
        paths = FoldPaths(units_dir, descriptors, studies, work / sensor)
        paths.out.mkdir(parents=True, exist_ok=True)
        pca_dir, environment = fold_environment(fold, paths)
        model = fold_model(fold, paths, None, pca_dir, environment, fs)
        models[sensor] = publish(model, out / sensor / algorithm)
    return models


def publish(model: Path, target: Path) -> Path:
    """The artifact folder ``model`` copied to ``target`` (atomically)."""
    import shutil

    from pipeline.io_utils import atomic_dir

    with atomic_dir(target) as tmp:
        for f in model.iterdir():
            shutil.copy2(f, tmp / f.name)
    return target


def fold_record(folder: Path) -> Mapping[str, Any]:
    """What a fold chose (its ``choice.json``)."""
    return json.loads((folder / "choice.json").read_text())  # type: ignore[no-any-return]
