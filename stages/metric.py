"""`adaptune metric kitti GT EST` (the KITTI devkit metric, any segment lengths) and `adaptune
metric rte GT EST --length L` (RTE, and evo's APE and RPE, of runs of any length)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from stages.common import FILE, echo_output, params_option
from stages.ingest import POSE_FORMATS

ALIGNMENTS = ("none", "origin", "se3", "sim3", "scale")
"""pipeline.metrics.trajectory_error.ALIGNMENTS (kept here so that --help imports no numpy)."""


@click.group()
def metric() -> None:
    """Trajectory error metrics."""


def _lengths(text: str | None) -> list[float] | None:
    if text is None:
        return None
    from pipeline.errors import ConfigError

    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ConfigError(f"--lengths must be metres separated by commas, got {text!r}") from None


@metric.command()
@click.argument("gt_poses", type=FILE)
@click.argument("est_poses", type=FILE)
@click.option("--lengths", "lengths_m", default=None,
              help="Segment lengths [m], comma-separated, e.g. 5,10,20 for a short run "
              "[params.yaml's devkit.lengths_m: the devkit's 100,...,800].")
@click.option("--step-frames", type=int, default=None,
              help="A segment starts every N frames [params.yaml's devkit.step_frames: 10].")
@params_option
@click.option("--json", "as_json", is_flag=True,
              help="Print JSON (t_err_pct, r_err_deg_per_m, segments, per_length).")
def kitti(gt_poses: Path, est_poses: Path, lengths_m: str | None, step_frames: int | None,
          params_path: Path | None, as_json: bool) -> None:
    """KITTI devkit error of EST_POSES against GT_POSES (KITTI pose files, camera frame).

    Segments of every length that fits (100..800 m unless --lengths), one starting every 10
    frames; the mean over all segments, as evaluate_odometry.cpp computes it.
    """
    from pipeline.config import load_section, validate_section
    from pipeline.metrics.kitti import evaluate_kitti_files
    from pipeline.metrics.section import DevkitSection

    devkit = load_section(params_path, "devkit", DevkitSection)
    given = {"lengths_m": _lengths(lengths_m), "step_frames": step_frames}
    devkit = validate_section(DevkitSection, "devkit", {
        **devkit.model_dump(), **{k: v for k, v in given.items() if v is not None}})
    result = evaluate_kitti_files(gt_poses, est_poses, devkit.lengths_m, devkit.step_frames)
    if as_json:
        echo_output(json.dumps(result, indent=1))
        return
    echo_output(f"t_err {result['t_err_pct']:.4f} %   r_err {result['r_err_deg_per_m']:.6f} "
                f"deg/m ({result['r_err_deg_per_m'] * 100:.4f} deg/100 m)   "
                f"{result['segments']} segments of "
                f"{', '.join(result['per_length'])} m, {result['frames']} frames")


@metric.command()
@click.argument("ground_truth", type=FILE)
@click.argument("estimates", nargs=-1, required=True, type=FILE)
@click.option("--length", "length_m", type=float, default=None,
              help="L [m]: the sub-trajectory length of the RTE (any length; KITTI's 100-800 m "
              "are `metric kitti`) [a GROUND_TRUTH sequence's own, where it has one; else "
              "required].")
@click.option("--align", "alignment", type=click.Choice(ALIGNMENTS), default="se3",
              show_default=True,
              help="How the estimate is aligned before APE and RPE: none; origin (first poses "
              "on each other); se3 (Umeyama); sim3 (Umeyama with scale, monocular methods); "
              "scale (the Sim(3) fit's scale alone, evo's -s).")
@click.option("--align-first", type=click.IntRange(min=1), default=None,
              help="Fit se3, sim3 or scale to the first N paired poses only (evo's "
              "--n_to_align) [every pose].")
@click.option("--delta", type=float, default=1.0, show_default=True,
              help="RPE: the distance between the poses of a pair, in --delta-unit.")
@click.option("--delta-unit", type=click.Choice(["frames", "m"]), default="frames",
              show_default=True, help="RPE: the unit of --delta (m: metres of path).")
@click.option("--all-pairs", is_flag=True,
              help="RPE: a pair from every frame, not consecutive pairs.")
@click.option("--pairs-from-reference", is_flag=True,
              help="RPE: pairs along the ground truth's path, not the aligned estimate's.")
@click.option("--gt-format", type=click.Choice(POSE_FORMATS), default="auto", show_default=True,
              help="Format of a GROUND_TRUTH pose file.")
@click.option("--est-format", type=click.Choice(POSE_FORMATS), default="auto",
              show_default=True, help="Format of the ESTIMATES pose files.")
@click.option("--plot", "plot_png", type=FILE, default=None,
              help="Write a PNG: the top view of the reference and the aligned estimates, the "
              "APE and the RTE along the path.")
@click.option("--json", "as_json", is_flag=True,
              help="Print JSON (rte, alignment, ape, rpe; a list of them for several "
              "estimates).")
def rte(ground_truth: Path, estimates: tuple[Path, ...], length_m: float | None, alignment: str,
        align_first: int | None, delta: float, delta_unit: str, all_pairs: bool,
        pairs_from_reference: bool, gt_format: str, est_format: str, plot_png: Path | None,
        as_json: bool) -> None:
    """RTE over --length L (the pipeline's per-start-frame error), and evo's APE and RPE
    (translation [m] and rotation angle [deg]) of each of ESTIMATES against GROUND_TRUTH;
    several estimates give one table, as evo_res does. Without --length, L is the
    GROUND_TRUTH sequence's own (a `data` source's length_m).

    Each is a sequence MCAP (its ground truth), a trajectory Parquet (`adaptune run`) or a pose
    file (KITTI, TUM, EuRoC CSV, 4x4 blocks). Stamped poses pair by time (10 ms), others by
    index.
    """
    from pipeline.metrics.trajectory_error import RpeSettings, compare_files

    rpe = RpeSettings(delta, delta_unit, all_pairs, pairs_from_reference)  # type: ignore[arg-type]
    truth, comparisons = compare_files(
        ground_truth, estimates, length_m, alignment, rpe, gt_format,  # type: ignore[arg-type]
        est_format, align_first)  # type: ignore[arg-type]
    if plot_png is not None:
        from pipeline.metrics.plot import plot_comparisons

        plot_comparisons(truth.T, comparisons, [Path(e).name for e in estimates], plot_png)
        click.echo(f"{plot_png}: top view, APE and RTE along the path of {len(estimates)} "
                   f"estimate{'s' if len(estimates) > 1 else ''}", err=True)
    summaries = [c.summary for c in comparisons]
    if as_json:
        echo_output(json.dumps(summaries[0] if len(summaries) == 1 else summaries, indent=1))
    elif len(summaries) == 1:
        echo_output(_report(summaries[0], rpe.describe()))
    else:
        echo_output(_table(summaries, rpe.describe()))


STATS = "rmse {rmse:.4f}  mean {mean:.4f}  median {median:.4f}  std {std:.4f}  " \
        "min {min:.4f}  max {max:.4f}"


def _report(r: dict[str, Any], rpe: str) -> str:
    """The text report of one estimate."""
    rt, al = r["rte"], r["alignment"]
    fitted = f", fitted to the first {al['poses']} poses" if al["poses"] < r["frames"] else ""
    return "\n".join([
        f"{r['frames']} frames, {r['path_m']:.1f} m of ground truth",
        f"RTE  L = {rt['length_m']:g} m, {rt['segments']} start frames: "
        f"t_err {rt['t_err_pct']:.4f} %  r_err {rt['r_err_deg_per_m']:.6f} deg/m",
        f"APE  alignment {al['method']} (scale {al['scale']:.4f}{fitted}), {r['frames']} poses",
        f"  translation [m]:   {STATS.format(**r['ape']['translation_m'])}",
        f"  rotation [deg]:    {STATS.format(**r['ape']['rotation_deg'])}",
        f"RPE  {rpe}, {r['rpe']['pairs']} pairs",
        f"  translation [m]:   {STATS.format(**r['rpe']['translation_m'])}",
        f"  rotation [deg]:    {STATS.format(**r['rpe']['rotation_deg'])}"])


def _table(summaries: list[dict[str, Any]], rpe: str) -> str:
    """One row an estimate, as evo_res tabulates results: RTE, and the RMSE of APE and RPE."""
    import pyarrow as pa

    from pipeline.text_table import format_table

    first = summaries[0]
    columns: dict[str, list[Any]] = {
        "estimate": [r["estimate"] for r in summaries],
        "frames": [r["frames"] for r in summaries],
        "rte_t_pct": [r["rte"]["t_err_pct"] for r in summaries],
        "rte_r_deg_per_m": [r["rte"]["r_err_deg_per_m"] for r in summaries],
        "ape_t_rmse_m": [r["ape"]["translation_m"]["rmse"] for r in summaries],
        "ape_r_rmse_deg": [r["ape"]["rotation_deg"]["rmse"] for r in summaries],
        "rpe_t_rmse_m": [r["rpe"]["translation_m"]["rmse"] for r in summaries],
        "rpe_r_rmse_deg": [r["rpe"]["rotation_deg"]["rmse"] for r in summaries],
        "scale": [r["alignment"]["scale"] for r in summaries],
    }
    head = (f"RTE over L = {first['rte']['length_m']:g} m; APE and RPE after "
            f"{first['alignment']['method']} alignment; RPE {rpe}; ground truth "
            f"{first['ground_truth']}")
    return head + "\n" + format_table(pa.table(columns), footer=False)
