"""Scans unlike the training data (docs/design.md, "Runtime"): the novelty distance of a
fitted model and the fallback parameters the runtime gives such scans.

The novelty distance is a quantile of every training frame's distance to the nearest frame of
another training sequence; the fallback is the adapter's defaults, or the joint study's best
parameters when they beat the defaults on every training sequence, or, per scan, whichever of
the two the surrogate predicts better there (``choose_fallback``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError


def novelty_distance(env: NDArray[np.float64], sequences: NDArray[np.str_],
                     quantile: float | None) -> float | None:
    """The ``quantile`` of every training frame's distance to the nearest frame of another
    training sequence (env (n_env, D) scaled environments, sequences (n_env,)): a scan farther
    than this from every training frame is unlike the training data (pipeline.runtime, step 3).
    None when disabled or with a single training sequence."""
    from scipy.spatial import cKDTree

    names = np.unique(sequences)
    if quantile is None or len(names) < 2:
        return None
    nearest = np.empty(len(env))
    for name in names:
        mine = sequences == name
        nearest[mine] = cKDTree(env[~mine]).query(env[mine])[0]
    return float(np.quantile(nearest, quantile))


NoveltyFallback = Literal["defaults", "fixed", "auto", "per_scan"]
NOVELTY_FALLBACKS: tuple[str, ...] = get_args(NoveltyFallback)


@dataclass
class FallbackEvidence:
    """The joint study's best parameters against the adapter defaults, per training sequence.

    fixed: the best 'ok' trial of the joint SMBO (the ``fixed`` stage); per_sequence: sequence
    -> (mean RTE [%] of the fixed parameters there, objective of that sequence's study trial run
    with the defaults: its mean RTE [%], or the failure penalty)."""

    fixed_trial: int
    fixed: dict[str, float]
    per_sequence: dict[str, tuple[float, float]]


def choose_fallback(
    mode: str, evidence: FallbackEvidence | None
) -> tuple[dict[str, float] | None, dict[str, Any]]:
    """Parameters for scans unlike every training frame (pipeline.runtime, step 3): None means
    the adapter's defaults. Returns (parameters or None, the record for the manifest).

    ``defaults``: the defaults. ``fixed``: the joint study's best parameters. ``auto``: the
    fixed parameters when they beat the defaults on every training sequence, else the defaults.
    The defaults are the out-of-distribution prior (hand-tuned for no environment in particular);
    they are dropped only when every environment seen shows them worse. Chosen on training data
    and dev composites, not on the validation sequence (docs/results/novelty-guard.md).
    ``per_scan``: both; the runtime gives each unfamiliar scan the one of the two the surrogate
    predicts better there (pipeline.runtime, step 3). Returns the fixed parameters, as the
    runtime needs them; the record's ``chosen`` is ``per_scan``.
    """
    if mode not in NOVELTY_FALLBACKS:
        raise ConfigError(f"novelty_fallback must be one of {NOVELTY_FALLBACKS}, got {mode!r}")
    if mode == "defaults":
        return None, {"mode": mode, "chosen": "defaults"}
    if evidence is None:
        if mode in ("fixed", "per_scan"):
            raise InputError(f"novelty_fallback {mode!r} needs the joint study (the fixed stage)")
        return None, {"mode": mode, "chosen": "defaults", "reason": "no joint study"}
    record: dict[str, Any] = {
        "mode": mode,
        "fixed_trial": evidence.fixed_trial,
        "per_sequence": {
            seq: {"fixed_rte_pct": f, "defaults_rte_pct": d}
            for seq, (f, d) in sorted(evidence.per_sequence.items())
        },
    }
    use_fixed = mode == "fixed" or (
        bool(evidence.per_sequence) and all(f < d for f, d in evidence.per_sequence.values())
    )
    if mode == "per_scan":
        record["chosen"] = "per_scan"
        return dict(evidence.fixed), record
    record["chosen"] = "fixed" if use_fixed else "defaults"
    return (dict(evidence.fixed) if use_fixed else None), record


def read_fallback_evidence(
    db_path: str | Path, algorithm: str, defaults: Mapping[str, float]
) -> FallbackEvidence | None:
    """``FallbackEvidence`` of ``algorithm`` from the results database (None without a
    successful joint trial or without the trials tables). A sequence whose study has no trial
    with the defaults is left out."""
    import duckdb

    from pipeline.tuning.layout import best_trial

    con = duckdb.connect(str(db_path), read_only=True)
    try:
        tables = {r[0] for r in con.execute("SELECT table_name FROM duckdb_tables()").fetchall()}
        if not {"trials", "rte_frames"} <= tables:
            return None
        joint = con.execute(
            "SELECT trial, status, objective, params_json FROM trials WHERE study = 'fixed' "
            "AND algorithm = ?", [algorithm]).fetchall()
        tid = best_trial((t, status, obj) for t, status, obj, _ in joint)
        if tid is None:
            return None
        best = next((t, params) for t, _, _, params in joint if t == tid)
        fixed_rte = con.execute(
            "SELECT sequence, avg(t_err_pct) FROM rte_frames WHERE study = 'fixed' "
            "AND algorithm = ? AND trial = ? GROUP BY sequence",
            [algorithm, best[0]],
        ).fetchall()
        studies = con.execute(
            "SELECT sequence, params_json, objective FROM trials WHERE study = 'trials' "
            "AND algorithm = ? AND objective IS NOT NULL ORDER BY sequence, trial",
            [algorithm],
        ).fetchall()
    finally:
        con.close()
    with_defaults: dict[str, float] = {}
    for seq, params_json, objective in studies:
        x = json.loads(params_json)
        if seq not in with_defaults and all(
            math.isclose(float(x.get(n, math.nan)), float(v), rel_tol=1e-9)
            for n, v in defaults.items()
        ):
            with_defaults[seq] = float(objective)
    per_sequence = {
        str(seq): (float(rte), with_defaults[seq])
        for seq, rte in fixed_rte
        if seq in with_defaults
    }
    fixed = {str(k): float(v) for k, v in json.loads(best[1]).items()}
    return FallbackEvidence(int(best[0]), fixed, per_sequence)


def novelty_fallback(
    db_path: str | Path, algorithm: str, space_json: list[dict[str, Any]], mode: str
) -> tuple[dict[str, float] | None, dict[str, Any]]:
    """``choose_fallback`` on the evidence of the results database (``mode`` 'defaults' reads
    nothing)."""
    if mode == "defaults":
        return choose_fallback(mode, None)
    defaults = {str(s["name"]): float(s["default"]) for s in space_json}
    return choose_fallback(mode, read_fallback_evidence(db_path, algorithm, defaults))
