"""Leave-one-sequence-out cross-validation of the surrogate (docs/design.md, "Surrogate").

Every training sequence in turn is held out: a ``Regressor`` of the configured surrogate is
fitted on the other sequences' rows and predicts the held-out rows. Reported in y units
(% RTE): MAE and RMSE; and a regret: for every held-out frame, the trial the surrogate ranks
best among that frame's trials against the best trial of that frame (mean of y_chosen - y_best,
and of y_best, y_chosen). Trials predicted exactly alike (the same k neighbours) tie; y_chosen
is then their mean y, what a random pick among them gives on average.

The *rank gap* (``rank_gap_median``, % RTE) is what the surrogate must tell apart: at every
held-out frame with two trials or more, the measured y of the worst trial there minus that of
the best (the candidates it ranks at that frame); their median over the held-out frames. A
surrogate whose MAE exceeds it errs by more than the typical spread it ranks: the evaluation
warns of it (``pipeline.report.checks``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.surrogates.rows import TrainingRows

if TYPE_CHECKING:
    from pipeline.surrogates.section import SurrogateSection

METHOD = "leave-one-sequence-out"
RECORD_KEYS = ("folds", "rows")
"""The bookkeeping of the summary (besides its text): folds and rows scored per fold; the rest
are the figures of ``metrics/surrogate.json`` (``pipeline.outputs.write_metrics``)."""


def _empty(note: str | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"method": METHOD, "folds": 0}
    if note:
        out["note"] = note
    return {**out, "mae": None, "rmse": None, "regret_mean": None, "rank_gap_median": None,
            "per_sequence": {}}


def cross_validate(
    rows: TrainingRows, settings: SurrogateSection, e_scale: float, x_scale: float
) -> dict[str, Any]:
    """Leave-one-sequence-out CV (module docstring). Held-out frames are subsampled to at most
    ``cv_max_frames`` per sequence (all trials of a kept frame stay, for the regret)."""
    from pipeline.surrogates import surrogate_class
    from pipeline.surrogates.target import from_target, to_target

    kind = surrogate_class(settings.model)

    feats = np.hstack([settings.w_e * rows.E / e_scale, rows.U * x_scale])
    t = to_target(rows.y, settings.target)
    seqs = sorted(set(rows.sequences.tolist()))
    if len(seqs) < 2:
        return _empty("needs >= 2 sequences")
    rng = np.random.default_rng(settings.seed)
    errs, per_seq, regrets, chosen, best, gaps = [], {}, [], [], [], []
    for seq in seqs:
        test = rows.sequences == seq
        train = ~test
        if train.sum() < settings.k:
            continue
        frames = np.unique(rows.frames[test])
        if len(frames) > settings.cv_max_frames:
            frames = rng.choice(frames, settings.cv_max_frames, replace=False)
        test &= np.isin(rows.frames, frames)
        model = kind.regressor(settings, rows.U.shape[1]).fit(feats[train], t[train])
        pred_y = from_target(model.predict(feats[test]), settings.target)
        true_y = rows.y[test]
        err = pred_y - true_y
        errs.append(err)
        per_seq[seq] = {
            "rows": int(test.sum()),
            "mae": float(np.mean(np.abs(err))),
            "rmse": float(np.sqrt(np.mean(err**2))),
        }
        fr = rows.frames[test]
        for f in np.unique(fr):
            sel = fr == f
            yt, yp = true_y[sel], pred_y[sel]
            y_chosen = float(yt[yp == yp.min()].mean())  # exact ties: their mean, not the first
            regrets.append(y_chosen - yt.min())
            chosen.append(y_chosen)
            best.append(yt.min())
            if len(yt) > 1:
                gaps.append(yt.max() - yt.min())
    if not errs:
        return _empty()
    e = np.concatenate(errs)
    return {
        "method": METHOD,
        "folds": len(per_seq),
        "mae": float(np.mean(np.abs(e))),
        "rmse": float(np.sqrt(np.mean(e**2))),
        "regret_mean": float(np.mean(regrets)),
        "y_chosen_mean": float(np.mean(chosen)),
        "y_oracle_mean": float(np.mean(best)),
        "rank_gap_median": float(np.median(gaps)) if gaps else None,
        "per_sequence": per_seq,
    }
