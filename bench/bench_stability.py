"""Is the selection chaotic? (issue 12) The toy validation schedule with the PCA and the
descriptors as they are, and changed by 1e-12 relative (what another BLAS's SVD or another
machine's descriptor does to their last digits), and with the candidate set shuffled (an order
that must not matter). Target: the toy validation RTE within 2 % of its value.

Needs the reproduction's outputs (`make repro`: model/ and data/sequences/); without them the
same counts are taken on the synthetic 614k-row model of bench_model.py and KITTI scans.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from common import Row, size, smoke

REPO = Path(__file__).resolve().parents[1]
NUDGE = 1e-12


def nudged(a: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``a`` changed by NUDGE relative, element by element."""
    return a * (1.0 + NUDGE * rng.standard_normal(a.shape))


def selections(model, descs: np.ndarray, pca: tuple | None = None,
               shuffle: int | None = None) -> np.ndarray:
    """(S, P) parameters selected from descriptors (S, F) in turn, as the runtime does (with
    the PCA arrays ``pca`` = (mean, scale, components) instead of the model's, or the
    candidates shuffled by seed ``shuffle``)."""
    from pipeline.runtime import Selector

    sel = Selector(model)
    if shuffle is not None:
        order = np.random.default_rng(shuffle).permutation(len(sel.candidates))
        sel.candidates = sel.candidates[order]
        sel.search = model.surrogate.search(sel.candidates, model.x_scale,
                                            {"subset_rows": sel.settings.subset_rows,
                                             "grouped": True})
    mean, scale, comp = pca or (model.pca_mean, model.pca_scale, model.pca_components)
    out = []
    for d in descs:
        e = ((np.sqrt(np.maximum(d.astype(np.float64), 0.0)) - mean) / scale) @ comp.T
        p = sel.select_environment(e * model.e_factor)
        out.append([p[n] for n in model.names])
    return np.array(out)


def toy_inputs() -> tuple[object, np.ndarray, Path | None, str]:
    """(model, descriptors of the selection scans, validation sequence or None, what it is)."""
    from pipeline.runtime import load_model
    from pipeline.selection import SelectionSettings
    from pipeline.sequence import SequenceReader

    seq = REPO / "data" / "sequences" / "composite_0.mcap"
    if (REPO / "model" / "manifest.json").is_file() and seq.is_file() and not smoke():
        model = load_model(REPO / "model")
        with SequenceReader(seq) as reader:
            step = round(SelectionSettings().period_s * 10)  # 10 Hz: a selection every step
            descs = np.stack([model.descriptor.describe(reader[i].points_lidar)
                              for i in range(0, len(reader), step)])
        return model, descs, seq, "toy validation composite_0"
    return (*synthetic_inputs(), None, "synthetic model, KITTI scans (no `make repro` outputs)")


def synthetic_inputs() -> tuple[object, np.ndarray]:
    import tempfile

    from bench_model import kitti_scans, synthetic_rows

    from pipeline.descriptors import NdtHistogram
    from pipeline.odometry.registry import get_adapter
    from pipeline.runtime import load_model
    from pipeline.surrogates.fit import fit_surrogate
    from pipeline.surrogates.section import SurrogateSection
    from pipeline.surrogates.writer import ArtifactInfo, write_artifact

    scans = kitti_scans()
    descs = np.stack([NdtHistogram().describe(s) for s in scans])
    space = get_adapter("ndt").space.to_json()
    rows, pca = synthetic_rows(descs, len(space))
    fitted = fit_surrogate(rows, space, SurrogateSection(n_sobol=size(1024, 64),
                                                         cv_max_frames=2))
    with tempfile.TemporaryDirectory() as tmp:
        write_artifact(Path(tmp) / "model", fitted, pca,
                       ArtifactInfo("ndt", space, NdtHistogram(),
                                    {"mode": "defaults", "chosen": "defaults"}))
        return load_model(Path(tmp) / "model"), descs


def rte_pct(model, seq: Path, values: np.ndarray) -> float:
    """Mean per-start-frame RTE [%] of the model's odometry with the selections ``values``
    (held for a period each) on ``seq``."""
    from pipeline.metrics.rte import per_frame_rte
    from pipeline.odometry import get_adapter, run_sequence
    from pipeline.odometry.base import Schedule
    from pipeline.sequence import SequenceReader

    with SequenceReader(seq) as reader:
        gt, stamps = reader.ground_truth(), np.asarray(reader.stamps_ns)
    step = -(-len(stamps) // len(values))
    held = {n: np.repeat(values[:, j], step)[:len(stamps)] for j, n in enumerate(model.names)}
    schedule = Schedule(np.arange(len(stamps), dtype=np.int32), held, stamps)
    traj = run_sequence(get_adapter(model.algorithm), seq, schedule)
    t_err, _ = per_frame_rte(gt, traj.T_world_lidar, 25.0)
    return float(np.nanmean(t_err))


def run() -> list[Row]:
    model, descs, seq, what = toy_inputs()
    rng = np.random.default_rng(0)
    ref = selections(model, descs)
    changed = {
        "PCA": selections(model, descs, (nudged(model.pca_mean, rng),
                                         nudged(model.pca_scale, rng),
                                         nudged(model.pca_components, rng))),
        "descriptors": selections(model, nudged(descs.astype(np.float64), rng)),
    }
    shuffled = [selections(model, descs, shuffle=s) for s in range(size(3, 1))]
    n = len(ref)
    rows = [Row(f"selections changed by a {NUDGE:g} relative change of the {k} ({what}, "
                f"{n} selections)", 100 * float(np.any(v != ref, axis=1).mean()), "%",
                "same run, unchanged", "0 %") for k, v in changed.items()]
    rows.append(Row("selections changed by shuffling the candidate set (3 orders)",
                    100 * float(np.mean([np.any(v != ref, axis=1).mean() for v in shuffled])),
                    "%", "same run, as given", "0 %"))
    if seq is not None:
        base = rte_pct(model, seq, ref)
        worst = max((abs(rte_pct(model, seq, v) / base - 1) if np.any(v != ref) else 0.0)
                    for v in [*changed.values(), *shuffled])
        rows.append(Row(f"toy validation RTE ({base:.3f} %), perturbed or shuffled vs as is",
                        100 * worst, "% rel.", "same run, unchanged", "<= 2 %"))
    return rows


if __name__ == "__main__":
    from common import format_table

    print(format_table(run()))
