"""Two runs of one suite, paired by world: does a change of the pipeline (multi-fidelity
trials against whole ones, issue 33) leave the suite's figures where they were?
(docs/results/verdict-protocol.md, "Two arms of one suite").

Both arms are a suite's metrics (``metrics/<family>.json``, ``studies.verdict.summary``) on
the same worlds: the reference (today's pipeline) and the candidate. Two views:

- **per ratio** (adaptive / fixed, adaptive / baseline, adaptive / min(baseline, fixed)): the
  candidate's geometric mean against the reference's 95 % interval. The candidate is *worse
  beyond the interval* when its geometric mean lies above the reference's upper end: the gate
  "not worse beyond their intervals";
- **per setting, paired**: per world the candidate's median RTE over the reference's, as a
  geometric mean with its bootstrap interval over worlds (``ratio_estimate``). An interval
  above 1 says the candidate's setting is measurably worse on these worlds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pipeline.errors import InputError
from studies.suites.runner import FIXED_SETTINGS
from studies.suites.statistics import CONFIDENCE, ratio_estimate
from studies.verdict.summary import RATIOS

SETTINGS = (*FIXED_SETTINGS, "adaptive")
"""The settings paired by world (``median_rte_pct`` of each world's entry)."""
KEYS = ("family", "suite", "seed_root", "per_world", "ratios")
"""What a suite's metrics hold that the comparison reads."""


def compare_arms(reference: Mapping[str, Any], candidate: Mapping[str, Any],
                 confidence: float = CONFIDENCE, resamples: int = 9999,
                 seed: int = 0) -> dict[str, Any]:
    """The candidate suite run against the reference (both ``metrics/<family>.json``).

    Returns {"worlds": n, "ratios": {name: {"reference": {geomean, low, high},
    "candidate": {...}, "worse_beyond_interval": bool}}, "paired": {setting: {value, low,
    high}}, "worse_beyond_intervals": bool}. InputError when either is not a suite's metrics,
    or the two do not hold the same family, suite and worlds.
    """
    _check_same_suite(reference, candidate)
    ratios = {name: _ratio_against(reference["ratios"][name], candidate["ratios"][name])
              for name in RATIOS}
    worlds = sorted(reference["per_world"])
    paired = {s: ratio_estimate([_median(candidate, w, s) / _median(reference, w, s)
                                 for w in worlds], confidence, resamples, seed).to_json()
              for s in SETTINGS}
    return {"family": reference["family"], "suite": reference["suite"], "worlds": len(worlds),
            "ratios": ratios, "paired": paired,
            "worse_beyond_intervals": any(r["worse_beyond_interval"] for r in ratios.values())}


def _ratio_against(reference: Mapping[str, Any], candidate: Mapping[str, Any]) -> dict[str, Any]:
    keep = ("geomean", "low", "high")
    high, value = reference["high"], candidate["geomean"]
    worse = high is not None and value is not None and value > high
    return {"reference": {k: reference[k] for k in keep},
            "candidate": {k: candidate[k] for k in keep}, "worse_beyond_interval": bool(worse)}


def _median(metrics: Mapping[str, Any], world: str, setting: str) -> float:
    return float(metrics["per_world"][world]["median_rte_pct"][setting])


def _check_same_suite(reference: Mapping[str, Any], candidate: Mapping[str, Any]) -> None:
    for arm, metrics in (("reference", reference), ("candidate", candidate)):
        missing = [k for k in KEYS if k not in metrics]
        if missing:
            raise InputError(f"the {arm} is not a suite's metrics (metrics/<family>.json), "
                             f"got no {missing[0]!r}")
    for key in ("family", "suite", "seed_root"):
        if reference.get(key) != candidate.get(key):
            raise InputError(f"the two arms must run the same suite, got {key}="
                             f"{reference.get(key)!r} against {candidate.get(key)!r}")
    a, b = set(reference["per_world"]), set(candidate["per_world"])
    if a != b:
        raise InputError(f"the two arms must run the same worlds, got {len(a ^ b)} that only "
                         f"one holds (e.g. {sorted(a ^ b)[0]})")
