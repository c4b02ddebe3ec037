"""Every registered surrogate (pipeline/surrogates/) side by side: leave-one-sequence-out CV
error and regret, fit time, one selection. The kNN (the paper's, the default) is the reference.

Rows: the real training rows of ``results/adaptune.duckdb`` when ``make repro`` has built it
(or of ``$ADAPTUNE_RESULTS_DB``; the surrogate stage's own settings from params.yaml), and the
synthetic rows of bench_model (8 sequences x 300 frames x 256 trials from real KITTI
descriptors) in every run.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_model import kitti_scans, synthetic_rows
from common import Row, best_of, size, smoke

REPO = Path(__file__).resolve().parents[1]


def compare(rows, space, base, what: str) -> list[Row]:
    """CV, fit time and one selection of every registered surrogate on ``rows``."""
    from pipeline.descriptors import NdtHistogram
    from pipeline.pca import Pca
    from pipeline.runtime import Selector, load_model
    from pipeline.surrogates import SURROGATES
    from pipeline.surrogates.fit import fit_surrogate
    from pipeline.surrogates.writer import ArtifactInfo, write_artifact

    out, ref = [], {}
    for name in SURROGATES:
        section = base.model_copy(update={"model": name})
        t0 = time.perf_counter()
        fitted = fit_surrogate(rows, space, section)
        fit_s = time.perf_counter() - t0
        cv = fitted.cv
        d = fitted.env.shape[1]
        pca = Pca(np.zeros(90), np.ones(90), np.eye(d, 90), np.ones(d) / d)
        with tempfile.TemporaryDirectory() as tmp:
            info = ArtifactInfo("gicp", space, NdtHistogram(), {"mode": "defaults",
                                                                "chosen": "defaults"})
            write_artifact(Path(tmp) / "model", fitted, pca, info)
            model = load_model(Path(tmp) / "model")
        sel = Selector(model)
        sel.novelty_distance = float("inf")
        envs = model.env[:: max(1, len(model.env) // 12)]

        def fresh(e: np.ndarray, sel: Selector = sel) -> None:
            sel.current_u = None
            sel.select_environment(e)

        select_ms = 1e3 * float(np.median([best_of(lambda e=e: fresh(e), repeat=2) for e in envs]))
        if not ref:
            ref = {"mae": cv["mae"], "regret": cv["regret_mean"], "ms": select_ms}
        label = "reference" if name == "knn" else "knn (same run)"
        out += [
            Row(f"{name}: LOSO CV MAE, {what}", cv["mae"], "% RTE",
                f"{label} {ref['mae']:.3f}", "-"),
            Row(f"{name}:   mean regret of the chosen trial (y_chosen {cv['y_chosen_mean']:.3f}, "
                f"oracle {cv['y_oracle_mean']:.3f})", cv["regret_mean"], "% RTE",
                f"{label} {ref['regret']:.3f}", "-"),
            Row(f"{name}:   fit + CV", fit_s, "s", "", "-"),
            Row(f"{name}:   one selection ({len(sel.candidates)} candidates)", select_ms, "ms",
                f"{label} {ref['ms']:.2f} ms", "-"),
        ]
    return out


def run() -> list[Row]:
    from pipeline.config import load_section
    from pipeline.descriptors.ndt_histogram import describe
    from pipeline.odometry.registry import get_adapter
    from pipeline.surrogates.rows import read_training_rows
    from pipeline.surrogates.section import SurrogateSection

    out = []
    db = Path(os.environ.get("ADAPTUNE_RESULTS_DB", REPO / "results" / "adaptune.duckdb"))
    if db.is_file() and not smoke():
        base = load_section(REPO / "params.yaml", "surrogate", SurrogateSection)
        algo, space, rows = read_training_rows(db, None, lambda a: get_adapter(a).space)
        out += compare(rows, space, base, f"{algo}, {len(rows.y) // 1000}k real rows "
                       f"({len(set(rows.sequences.tolist()))} sequences, make repro)")
    descs = np.stack([describe(s) for s in kitti_scans()])
    space = get_adapter("gicp").space.to_json()
    rows, _ = synthetic_rows(descs, len(space))
    base = SurrogateSection(n_sobol=size(1024, 64), cv_max_frames=size(20, 2))
    out += compare(rows, space, base, f"{len(rows.y) // 1000}k synthetic rows")
    return out


if __name__ == "__main__":
    from common import format_table

    print(format_table(run()))
