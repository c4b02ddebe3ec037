"""Leave one training sequence out: how well the portfolio selector's choice carries over
(docs/results/selector-dev.md).

Not a `make bench` module: ``python experiments/portfolio_loso.py --db
PROJECT/results/adaptune.duckdb [--k 20,100,350]``, after ``adaptune rte --portfolio`` built
the database. It reads the ``portfolio_rows`` view (every member of the portfolio at every
training frame, y the RTE [%] of the sub-trajectory from that frame), then for every training
sequence held out and every frame of it chooses the member as the portfolio selector does
(``surrogate.rows: portfolio``, members only, their own runs kept apart): the lowest mean
log1p(y) over the k frames of the other sequences nearest in the environment E (one scale for
every dimension, as ``pipeline.surrogates.fit`` scales it, so the nearest frames are the same).
Printed per k: the mean over the held-out frames of the chosen member's y, against the single
best member of the other sequences (the portfolio's SBS), the best of the other sequences'
frames of the held-out frame's environment label (a perfect classifier's choice) and the best
member of each held-out frame (the frame oracle), each also against the fixed set
(``--reference``: the verdict's statistic); ``winners_k``: the kNN among the fixed set and each
label's choice only. Then per environment label, where the headroom lives: the label's best
member in sample and the one chosen on the other sequences, against the fixed set.
``--also DB`` adds a second portfolio's members measured on the same frames (a finer grid:
docs/results/selector-dev.md, "Finer candidates near the fixed set"). A proxy of the dev
suite, not a replacement: a frame's y is one sub-trajectory of a run with one set, not a
schedule's run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def frame_table(db: Path, portfolio: Path | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """E (F, D) of every training frame, y (F, M) of every member there [%], the sequence
    and the environment label (F,) of each frame; members by trial number (trial i is member
    i in every sequence). ``portfolio``: the portfolio study's folder (default: beside the
    database)."""
    import duckdb

    from pipeline.odometry.base import ParameterSpace
    from pipeline.surrogates.rows import read_training_rows
    from pipeline.tuning.table import read_space

    def space_of(algorithm: str) -> ParameterSpace:  # the portfolio's trials hold the space
        return read_space(portfolio or db.parent / "portfolio", algorithm)

    _, _, rows = read_training_rows(db, None, space_of, "portfolio")
    keys = np.char.add(np.char.add(rows.sequences.astype(str), ":"), rows.frames.astype(str))
    frames, frame_of = np.unique(keys, return_inverse=True)
    members = np.unique(rows.trials)
    y = np.full((len(frames), len(members)), np.nan)
    y[frame_of, np.searchsorted(members, rows.trials)] = rows.y
    if np.isnan(y).any():
        raise SystemExit(f"{db}: {int(np.isnan(y).sum())} (frame, member) cells without a row")
    first = np.zeros(len(frames), np.int64)
    first[frame_of[::-1]] = np.arange(len(frame_of))[::-1]
    con = duckdb.connect(str(db), read_only=True)
    labels = dict(((s, f), lab) for s, f, lab in
                  con.execute("SELECT sequence, frame, label FROM frame_labels").fetchall())
    con.close()
    seq = rows.sequences.astype(str)[first]
    label = np.array([labels.get((s, int(f)), "") for s, f in zip(seq, rows.frames[first],
                                                                   strict=True)])
    return rows.E[first], y, seq, label


def same_frames(other: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], E: np.ndarray,
                seq: np.ndarray, label: np.ndarray) -> np.ndarray:
    """The second portfolio's y (F, M2) after checking that its frames are the first's: the
    same sequences, labels and descriptors (``frame_table`` orders frames alike)."""
    E2, y2, seq2, label2 = other
    if len(E2) != len(E) or not ((seq2 == seq).all() and (label2 == label).all()
                                 and np.allclose(E2, E)):
        raise SystemExit("--also: its frames are not the first database's")
    return y2


def loso(E: np.ndarray, y: np.ndarray, seq: np.ndarray, label: np.ndarray,
         ks: list[int], ref: int) -> dict[str, tuple[float, float, float]]:
    """Per choice: the mean y of the chosen member over every held-out frame, and the geometric
    means over held-out sequences of its mean y / the SBS's and / member ``ref``'s (the fixed
    set's: the verdict's statistic); the choices: the kNN's per k (``winners_k``: among
    ``ref`` and each label's member of ``label`` only, the portfolio cut to the sets tuned per
    environment), the SBS's (the lowest mean log1p(y) over the other sequences' frames), the
    constant's and the label's (the member best on the other sequences, or on
    those frames of them with the held-out frame's true environment label, by the class oracle's
    score: a perfect environment classifier's choice; ``label_sensor``: of the sequences of the
    held-out one's sensor only) and the frame oracle's."""
    from scipy.spatial import cKDTree

    t = np.log1p(np.maximum(y, 0.0))
    chosen: dict[int, list[np.ndarray]] = {k: [] for k in ks}
    winners: dict[int, list[np.ndarray]] = {k: [] for k in ks}
    sbs, oracle, by_label, robust, by_sensor = [], [], [], [], []
    # the coverage model's train_sensors [hdl32, hdl64]: sequence <world>_<i> has sensor i % 2
    sensor = np.array([int(s.rsplit("_", 1)[1]) % 2 for s in seq])
    for s in np.unique(seq):
        held, train = seq == s, seq != s
        tree = cKDTree(E[train])
        kmax = min(max(ks), int(train.sum()))
        _, idx = tree.query(E[held], k=kmax)
        idx = idx.reshape(int(held.sum()), kmax)
        cum = np.cumsum(t[train][idx], axis=1)  # (frames, kmax, members)
        for k in ks:
            kk = min(k, kmax)
            pick = np.argmin(cum[:, kk - 1, :], axis=1)
            chosen[k].append(y[held][np.arange(int(held.sum())), pick])
        sbs.append(y[held][:, int(np.argmin(t[train].mean(axis=0)))])
        best = {lab: _robust_best(y, seq, train & (label == lab))
                for lab in np.unique(label[held]) if (train & (label == lab)).any()}
        cut = np.array(sorted({ref, *best.values()}))  # ISAC-style: each label's tuned set
        for k in ks:
            pick = cut[np.argmin(cum[:, min(k, kmax) - 1, cut], axis=1)]
            winners[k].append(y[held][np.arange(int(held.sum())), pick])
        by_label.append(np.array([y[i, best.get(label[i], 0)] for i in np.flatnonzero(held)]))
        robust.append(y[held][:, _robust_best(y, seq, train)])
        mine = train & (sensor == sensor[held][0])
        best = {lab: _robust_best(y, seq, mine & (label == lab))
                for lab in np.unique(label[held]) if (mine & (label == lab)).any()}
        by_sensor.append(np.array([y[i, best.get(label[i], 0)] for i in np.flatnonzero(held)]))
        oracle.append(y[held].min(axis=1))
    lists = {**{f"k{k}": v for k, v in chosen.items()},
             **{f"winners_k{k}": v for k, v in winners.items()}, "sbs": sbs, "constant": robust,
             "reference": [y[seq == s][:, ref] for s in np.unique(seq)],
             "label": by_label, "label_sensor": by_sensor, "frame_oracle": oracle}
    sbs_means = np.array([np.mean(v) for v in sbs])
    ref_means = np.array([np.mean(v) for v in lists["reference"]])

    def ratio(v: list[np.ndarray], to: np.ndarray) -> float:
        return float(np.exp(np.mean(np.log(np.array([np.mean(x) for x in v]) / to))))

    return {name: (float(np.mean(np.concatenate(v))), ratio(v, sbs_means), ratio(v, ref_means))
            for name, v in lists.items()}


def _robust_best(y: np.ndarray, seq: np.ndarray, rows: np.ndarray) -> int:
    """The member best over the sequences of ``rows`` (F,) bool by the class oracle's score
    (``studies.verdict.headroom.least_log_ratio`` of each sequence's mean y per member), which
    no single sequence's failures rule."""
    from studies.verdict.headroom import least_log_ratio

    best = least_log_ratio([y[rows & (seq == s)].mean(axis=0) for s in np.unique(seq[rows])])
    if best is None:
        raise SystemExit("no sequence where every member has a finite, positive mean RTE")
    return best


def label_gains(y: np.ndarray, seq: np.ndarray, label: np.ndarray, ref: int,
                min_frames: int = 30) -> list[tuple[str, int, float, int, float, float]]:
    """Where the headroom lives, per environment label against member ``ref`` (the fixed
    set): per label, over the sequences with at least ``min_frames`` frames of it, each
    sequence's mean y per member on those frames, then (label, sequences, ref's mean y there
    [%], the in-sample best member, its geometric-mean ratio to ref over those sequences, and
    the ratio of the member chosen on the other sequences, leave one out). A ratio near 1 with
    the label's best chosen in sample: no set of the portfolio beats ref in that environment."""
    rows = []
    for lab in np.unique(label):
        names = [s for s in np.unique(seq) if ((seq == s) & (label == lab)).sum() >= min_frames]
        if len(names) < 2:
            continue
        means = np.log(np.array([y[(seq == s) & (label == lab)].mean(axis=0) for s in names]))
        gain = means - means[:, [ref]]  # (sequences, members) log ratio to member ref
        best = int(np.argmin(gain.mean(axis=0)))
        held_out = [gain[i, int(np.argmin(np.delete(gain, i, axis=0).mean(axis=0)))]
                    for i in range(len(names))]
        rows.append((str(lab), len(names), float(np.exp(means[:, ref]).mean()), best,
                     float(np.exp(gain[:, best].mean())), float(np.exp(np.mean(held_out)))))
    return rows


def member_params(portfolio: Path) -> list[str]:
    """Each member's parameters as text, by trial number (from the portfolio's trials)."""
    from pipeline.tuning.layout import read_trials_tables

    table = read_trials_tables(portfolio).to_pydict()
    params = dict(zip(table["trial"], table["params_json"], strict=True))
    return [params[i] for i in range(len(params))]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, required=True)
    parser.add_argument("--portfolio", type=Path, default=None,
                        help="The portfolio study's folder [default: DB's folder/portfolio].")
    parser.add_argument("--also", type=Path, default=None,
                        help="A second portfolio's database on the same frames (its study in "
                             "its folder/portfolio): its members join the first's.")
    parser.add_argument("--k", default="20,100,350,700,1000,1400,3000")
    parser.add_argument("--reference", type=int, default=-1,
                        help="The member the ratios and the labels' gains are against "
                             "[default: the first portfolio's last, the fixed set with "
                             "portfolio.fixed].")
    parser.add_argument("--first", type=int, default=None,
                        help="Only the sequences <world>_<i> with i < FIRST (a learning curve).")
    args = parser.parse_args(argv)
    portfolio = args.portfolio or args.db.parent / "portfolio"
    E, y, seq, label = frame_table(args.db, portfolio)
    names = member_params(portfolio)
    args.reference = args.reference % len(names)  # before --also's members join
    if args.also is not None:
        y = np.hstack([y, same_frames(frame_table(args.also), E, seq, label)])
        names += member_params(args.also.parent / "portfolio")
    if args.first is not None:
        keep = np.array([int(s.rsplit("_", 1)[1]) < args.first for s in seq])
        E, y, seq, label = E[keep], y[keep], seq[keep], label[keep]
    ks = [int(k) for k in args.k.split(",")]
    result = loso(E, y, seq, label, ks, args.reference)
    print(f"{args.db}: {len(np.unique(seq))} sequences, {len(E)} frames, {y.shape[1]} members; "
          "the member chosen per held-out frame (leave one sequence out): mean RTE [%] over "
          "the frames, geometric mean over the sequences of its mean / the SBS's and / member "
          f"{args.reference}'s")
    for name, (mean, to_sbs, to_reference) in result.items():
        print(f"  {name:14s} {mean:.3f}  {to_sbs:.3f}  {to_reference:.3f}")
    ref = args.reference
    print(f"Per environment label against member {ref} {names[ref]}: sequences, its mean RTE "
          "[%], the label's best member in sample and its geometric-mean ratio, the ratio of "
          "the member chosen on the other sequences (leave one out)")
    for lab, n, ref_rte, best, ratio, held_out in label_gains(y, seq, label, ref):
        print(f"  {lab:8s} {n:3d}  {ref_rte:.3f}  {best:3d} {names[best]:44s} {ratio:.3f}  "
              f"{held_out:.3f}")


if __name__ == "__main__":
    main()
