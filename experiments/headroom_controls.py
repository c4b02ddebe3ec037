"""Is the in-distribution headroom per environment, or a better single set?
(docs/results/selector-dev.md, "... and what the headroom is made of")

Not a `make bench` module, and it runs nothing: ``python experiments/headroom_controls.py
--headroom verdict/results/headroom [--metrics verdict/metrics/headroom.json]`` reads the
oracles stage's output. Every world's ``candidates.json`` holds the mean RTE [%] of every
candidate of the frozen set per environment label on the selection replica (R + 1), a run
the suite never scores, and ``rte.parquet`` the labels of the sub-trajectories. On that replica
alone, each world's RTE under a choice is the label means weighted by the world's
sub-trajectories per label (switching costs not paid: a proxy of the stitched runs), for:

- **SBS**: the fixed set (a member of the candidate set);
- **constant**: the one candidate that was best on the *other* worlds over the whole world,
  by the class oracle's score (``least_log_ratio``: the mean log ratio to each world's median
  candidate): a single set chosen on 39 worlds instead of the joint study's 12 training sequences;
- **class**: per label, the candidate best on the other worlds with that label (the class
  oracle's choice, ``studies.verdict.headroom.class_choice``);
- **class and sensor**: the same from the other worlds of the world's sensor only;
- **label oracle**: per label, the world's own best candidate on this replica (in-sample: an
  upper bound with the replica's luck in it).

Printed: the geometric mean over worlds of each against SBS and class against constant, with
the paired bootstrap 95 % interval over worlds (``studies.suites.statistics.ratio_estimate``).
If class / constant holds 1, the headroom over SBS is a better fixed set, which more tuning data
buys, not a choice per environment.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def read_worlds(headroom: Path) -> tuple[list[dict], list[dict[str, float]]]:
    """Per world (sorted by name): {name, label_rte {label: (C,)}, counts {label: n}}; and the
    candidate set."""
    import pyarrow.parquet as pq

    worlds, candidates = [], None
    for d in sorted(p for p in headroom.iterdir() if (p / "candidates.json").is_file()):
        c = json.loads((d / "candidates.json").read_text())
        candidates = c["candidates"]
        table = pq.read_table(d / "rte.parquet").to_pydict()
        scored = np.isfinite(np.asarray(table["oracle/0"], np.float64))
        labels = np.asarray(table["label"])[scored]
        counts = {lab: int((labels == lab).sum()) for lab in c["selection_replica_rte_pct"]}
        sensor = json.loads((d / "world.json").read_text())["sensor"]
        worlds.append({"name": d.name, "counts": counts, "sensor": sensor,
                       "label_rte": {lab: np.asarray(v, np.float64)
                                     for lab, v in c["selection_replica_rte_pct"].items()}})
    if candidates is None:
        raise SystemExit(f"{headroom}: no world with candidates.json (run the oracles stage)")
    return worlds, candidates


def world_rte(world: dict, choice: dict[str, int]) -> float:
    """The world's RTE [%] when each label gets its chosen candidate: label means weighted by
    the label's sub-trajectories."""
    total = sum(world["counts"][lab] * world["label_rte"][lab][c] for lab, c in choice.items()
                if world["counts"][lab] > 0)
    return total / sum(world["counts"][lab] for lab in choice if world["counts"][lab] > 0)


def whole_world(world: dict) -> np.ndarray:
    """(C,) the world's RTE under every candidate held over the whole world."""
    n = len(next(iter(world["label_rte"].values())))
    return np.array([world_rte(world, dict.fromkeys(world["label_rte"], c)) for c in range(n)])


def controls(worlds: list[dict], sbs: int) -> dict[str, np.ndarray]:
    """Per world, its RTE under each choice (module docstring): {choice: (W,)}."""
    from studies.verdict.headroom import class_choice, least_log_ratio

    whole = [whole_world(w) for w in worlds]
    out: dict[str, list[float]] = {"sbs": [], "constant": [], "class": [], "class_sensor": [],
                                   "label_oracle": []}
    for i, w in enumerate(worlds):
        constant = least_log_ratio([v for j, v in enumerate(whole) if j != i])
        out["sbs"].append(whole[i][sbs])
        out["constant"].append(whole[i][constant])
        out["class"].append(world_rte(w, class_choice(w["name"], {
            o["name"]: o["label_rte"] for o in worlds})))
        out["class_sensor"].append(world_rte(w, class_choice(w["name"], {
            o["name"]: o["label_rte"] for o in worlds if o["sensor"] == w["sensor"]})))
        out["label_oracle"].append(world_rte(w, {lab: int(np.nanargmin(v))
                                                 for lab, v in w["label_rte"].items()}))
    return {k: np.asarray(v) for k, v in out.items()}


def main(argv: list[str] | None = None) -> None:
    from studies.suites.statistics import ratio_estimate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--headroom", type=Path, default=Path("verdict/results/headroom"))
    parser.add_argument("--metrics", type=Path, default=Path("verdict/metrics/headroom.json"))
    args = parser.parse_args(argv)
    worlds, candidates = read_worlds(args.headroom)
    fixed = json.loads(args.metrics.read_text())["fixed"]
    sbs = next(i for i, c in enumerate(candidates)
               if all(abs(c[n] - v) < 1e-9 for n, v in fixed.items()))
    rte = controls(worlds, sbs)
    print(f"{args.headroom}: {len(worlds)} worlds, {len(candidates)} candidates (SBS = "
          f"candidate {sbs}); the selection replica's label means, geometric mean over worlds "
          "(95 % interval)")
    for name, ref in (("constant", "sbs"), ("class", "sbs"), ("class_sensor", "sbs"),
                      ("label_oracle", "sbs"), ("class", "constant"),
                      ("class_sensor", "class")):
        e = ratio_estimate(rte[name] / rte[ref])
        wins = int((rte[name] < rte[ref]).sum())
        print(f"  {name} / {ref}: {e.value:.3f} ({e.low:.3f}-{e.high:.3f}), "
              f"{wins}/{len(worlds)} worlds better")


if __name__ == "__main__":
    main()
