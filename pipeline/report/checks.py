"""The warnings the evaluation carries: in metrics/evaluation.json (``warnings``, booleans that
``dvc metrics show`` lists) and at the top of report/report.md.

- ``adaptive_worse_than_baseline`` / ``adaptive_worse_than_fixed``: adaptive's mean RTE on the
  validation split (the headline split when none is evaluated) is above the baseline's / the
  fixed parameters'.
- ``surrogate_error_exceeds_rank_gap``: the surrogate's leave-one-sequence-out MAE (% RTE) is
  above its rank gap, the median over the held-out frames of the RTE gap between the worst and
  the best trial there (``pipeline.surrogates.cross_validation``): it errs by more than the
  spread it must rank, so its choices are close to chance. Only where the model's manifest
  gives both (not without ``--model``, nor with fewer than two training sequences).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def checked_split(m: Mapping[str, Any]) -> str:
    """The split the warnings judge: validation when evaluated, else the headline split."""
    return "validation" if "validation" in m["splits"] else str(m["headline_split"])


def surrogate_error_exceeds_rank_gap(cv: Mapping[str, Any] | None) -> bool | None:
    """Whether the cross-validation ``cv`` (the manifest's ``cross_validation``) has an MAE
    above its rank gap; None when it gives no figure for either."""
    if cv is None or cv.get("mae") is None or cv.get("rank_gap_median") is None:
        return None
    return bool(cv["mae"] > cv["rank_gap_median"])


def evaluation_warnings(m: Mapping[str, Any],
                        cv: Mapping[str, Any] | None) -> dict[str, bool]:
    """The warning flags (module docstring) of the evaluation summary ``m`` and the
    surrogate's cross-validation ``cv`` (the manifest's ``cross_validation``; None: unknown)."""
    rte = m["splits"][checked_split(m)]["rte_pct"]
    out = {"adaptive_worse_than_baseline": bool(rte["adaptive"] > rte["baseline"]),
           "adaptive_worse_than_fixed": bool(rte["adaptive"] > rte["fixed"])}
    surrogate = surrogate_error_exceeds_rank_gap(cv)
    if surrogate is not None:
        out["surrogate_error_exceeds_rank_gap"] = surrogate
    return out


def warning_lines(m: Mapping[str, Any], cv: Mapping[str, Any] | None) -> list[str]:
    """One sentence per warning raised, with its figures (report.md, the stage's summary)."""
    flags = evaluation_warnings(m, cv)
    split = checked_split(m)
    rte = m["splits"][split]["rte_pct"]
    lines = []
    for other in ("baseline", "fixed"):
        if flags[f"adaptive_worse_than_{other}"]:
            lines.append(f"adaptive is worse than {other} on the {split} split: "
                         f"{rte['adaptive']:.3f} % against {rte[other]:.3f} % "
                         f"(x{rte['adaptive'] / rte[other]:.2f})")
    if flags.get("surrogate_error_exceeds_rank_gap") and cv is not None:
        lines.append(f"the surrogate's cross-validated error (MAE {cv['mae']:.3f} %) exceeds "
                     f"the median RTE gap between the best and the worst trial it ranks at a "
                     f"held-out frame ({cv['rank_gap_median']:.3f} %): its choices of parameters "
                     "are close to chance")
    return lines
