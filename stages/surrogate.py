"""`adaptune surrogate`: fit the kNN surrogate from the results database, write model/."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

import click
from pydantic import Field

from pipeline.config import Section, load_section
from stages.common import params_option


class SurrogateSection(Section):
    """params.yaml ``surrogate`` (pipeline/surrogate.py and pipeline/runtime.py document them)."""

    k: int = Field(5, ge=1)
    w_e: float = Field(1.0, gt=0)
    w_x: float = Field(1.0, gt=0)
    target: Literal["log", "linear"] = "log"
    n_sobol: int = Field(1024, ge=0)
    seed: int = 0
    cv_max_frames: int = Field(200, ge=1)
    period_s: float = Field(1.0, gt=0)
    hysteresis: float = Field(0.02, ge=0)
    min_scan_points: int = Field(1000, ge=0)
    subset_rows: int = Field(4096, ge=1)
    refine_iters: int = Field(4, ge=0)
    novelty_quantile: float | None = Field(1.0, gt=0, le=1)
    novelty_fallback: Literal["defaults", "fixed", "auto"] = "auto"


@click.command()
@params_option
@click.option(
    "--db",
    "db_path",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="results/adaptune.duckdb (surrogate_rows view).",
)
@click.option(
    "--pca",
    "pca_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="The PCA folder written by `adaptune descriptors`.",
)
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="The artifact folder (model/).",
)
@click.option("--algorithm", default=None, help="Algorithm of the rows (default: the only one).")
@click.option(
    "--metrics",
    "metrics_path",
    default=None,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the CV error here (JSON).",
)
def surrogate(
    params_path: Path,
    db_path: Path,
    pca_dir: Path,
    out: Path,
    algorithm: str | None,
    metrics_path: Path | None,
) -> None:
    """Fit the kNN surrogate S(E, x) ~ y and write the deployable artifact."""
    from pipeline.descriptor import DescriptorConfig
    from pipeline.io_utils import atomic_write_text
    from pipeline.odometry.registry import get_adapter
    from pipeline.surrogate import (
        ArtifactInfo,
        Pca,
        SurrogateSettings,
        fit_surrogate,
        novelty_fallback,
        read_training_rows,
        write_artifact,
    )
    from stages.descriptors import DescriptorsSection

    p = load_section(params_path, "surrogate", SurrogateSection)
    d = load_section(params_path, "descriptors", DescriptorsSection)
    pca = Pca.load(pca_dir)
    algo, space, rows = read_training_rows(db_path, algorithm, lambda a: get_adapter(a).space)
    settings = SurrogateSettings(p.k, p.w_e, p.w_x, p.target, p.n_sobol, p.seed, p.cv_max_frames,
                                 p.novelty_quantile)
    fitted = fit_surrogate(rows, space, settings)
    selection: dict[str, Any] = {
        "period_s": p.period_s,
        "hysteresis": p.hysteresis,
        "min_scan_points": p.min_scan_points,
        "subset_rows": p.subset_rows,
        "refine_iters": p.refine_iters,
    }
    fallback, record = novelty_fallback(db_path, algo, space, p.novelty_fallback)
    selection["novelty_fallback"] = record
    if fallback is not None:
        selection["novelty_fallback_params"] = fallback
    # the descriptor settings the PCA was fitted with win (pca.json); params only as fallback
    descriptor = (
        DescriptorConfig.from_json(pca.descriptor)
        if pca.descriptor
        else DescriptorConfig(
            d.voxel_size_m, d.min_points, d.t_e, d.range_bins, d.bin_m, d.normalize
        )
    )
    info = ArtifactInfo(
        algo, space, descriptor, selection, {"db": str(db_path), "pca": str(pca_dir)}
    )
    manifest = write_artifact(out, fitted, pca, info)
    cv = manifest["cross_validation"]
    if metrics_path is not None:
        atomic_write_text(metrics_path, json.dumps({"algorithm": algo, **cv}, indent=2))
    click.echo(
        f"{algo}: {fitted.summary['rows']} rows, {fitted.summary['environments']} frames "
        f"-> {out}; LOSO CV MAE {cv['mae']}, RMSE {cv['rmse']}, regret {cv['regret_mean']}",
        err=True,
    )
