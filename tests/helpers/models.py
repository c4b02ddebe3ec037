"""Model artifacts and tiny sequences from the real KITTI scans (tests/conftest.py's
``kitti_root``): descriptors of the 40 mini scans, synthetic training rows whose best parameter
depends on the environment, a fitted artifact, and short sequence MCAPs."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.descriptors import NdtHistogram
from pipeline.descriptors.ndt_histogram import describe
from pipeline.odometry.registry import get_adapter
from pipeline.pca import Pca, fit_pca
from pipeline.selection import SelectionSettings
from pipeline.sequence import SequenceInfo, SequenceWriter
from pipeline.surrogates.fit import fit_surrogate
from pipeline.surrogates.rows import TrainingRows
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.writer import ArtifactInfo, write_artifact

SEQS = ("01", "04", "06", "10")
SEL = SelectionSettings(hysteresis=0.0, subset_rows=512, refine_iters=0, window=1)
"""The selector settings the tests of the models built here use (no hysteresis, no pattern
search, the newest scan only; a kd-tree subset of 512 rows)."""
DEFAULTS_FALLBACK = {"mode": "defaults", "chosen": "defaults"}
"""The novelty fallback record of a model whose unfamiliar scans get the defaults."""


def kitti_scan(kitti_root: Path, seq: str, frame: int) -> np.ndarray:
    path = kitti_root / "sequences" / seq / "velodyne" / f"{frame:06d}.bin"
    return np.fromfile(path, np.float32).reshape(-1, 4)


@functools.lru_cache(maxsize=2)
def kitti_descriptors(kitti_root: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sequence names (40,), frames (40,), descriptors (40, 90)) of the KITTI mini scans."""
    names, frames, desc = [], [], []
    for seq in SEQS:
        for f in range(10):
            names.append(seq)
            frames.append(f)
            desc.append(describe(kitti_scan(kitti_root, seq, f)))
    return np.array(names), np.array(frames), np.stack(desc)


def true_y(E: np.ndarray, U: np.ndarray) -> np.ndarray:
    """A synthetic RTE [%]: the best first parameter depends on the environment."""
    best = 1.0 / (1.0 + np.exp(-E[:, 0] / 2.0))
    return 0.3 + 4.0 * (U[:, 0] - best) ** 2 + 0.5 * (U[:, 1] - 0.3) ** 2


def synthetic_rows(kitti_root: Path, trials: int = 24, seed: int = 0) -> tuple[TrainingRows, Pca]:
    names, frames, desc = kitti_descriptors(kitti_root)
    pca = fit_pca(desc, 10, list(SEQS))
    pca.descriptor = NdtHistogram().to_json()
    E_f = pca.transform(desc)
    rng = np.random.default_rng(seed)
    U_trials = {s: rng.random((trials, 2)) for s in SEQS}  # each sequence has its own trials
    E, U, S, F, T = [], [], [], [], []
    for i, (s, f) in enumerate(zip(names, frames, strict=True)):
        E.append(np.repeat(E_f[i][None], trials, 0))
        U.append(U_trials[s])
        S += [s] * trials
        F += [f] * trials
        T += list(range(trials))
    E, U = np.vstack(E), np.vstack(U)
    y = true_y(E, U) * np.exp(rng.normal(0, 0.05, len(U)))
    return TrainingRows(E, U, y, np.array(S), np.array(F), np.array(T)), pca


def build_model(
    out: Path,
    kitti_root: Path,
    algorithm: str = "ndt",
    trials: int = 24,
    settings: SurrogateSection | None = None,
    fallback: dict[str, Any] | None = None,
    fallback_params: dict[str, float] | None = None,
) -> Path:
    """A model artifact at ``out`` fitted on ``synthetic_rows`` (a small candidate set and
    cross-validation unless ``settings`` says otherwise), with the novelty ``fallback``."""
    rows, pca = synthetic_rows(kitti_root, trials)
    space = get_adapter(algorithm).space.to_json()
    fitted = fit_surrogate(rows, space, settings or SurrogateSection(n_sobol=256, cv_max_frames=5))
    info = ArtifactInfo(algorithm, space, NdtHistogram(), fallback or DEFAULTS_FALLBACK,
                        fallback_params)
    write_artifact(out, fitted, pca, info)
    return out


def write_tiny_sequence(path: Path, kitti_root: Path, seq: str, n: int = 4, step: int = 3) -> None:
    with SequenceWriter(path, SequenceInfo(name=path.stem, sensor="hdl64", source="kitti")) as w:
        for f in range(n):
            w.add(
                1_000_000_000 + f * 100_000_000, kitti_scan(kitti_root, seq, f)[::step], np.eye(4)
            )
