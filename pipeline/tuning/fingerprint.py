"""What defines a study: its fingerprint, stored with its trials table, which a resume must
match.

A study's proposals and scores depend on the adapter and its options, the parameter space,
the seed, L (``length_m``), the penalty, the jump limit, the time limit (a trial past it
fails), TPE's start-up count, how far the proposals lag the results (``told_lag``, from the
workers), the pruner's settings, the rungs of successive halving, the parameters it tries
first (a warm start), what a failed sequence does to a trial (``failures``) and the sequences'
content. Resuming with any of them changed would
silently mix two studies, so ``check_fingerprint`` refuses it in one line naming every
difference. What may change on a resume: ``iterations`` (a study can be extended),
``retries``, ``dask``.

Sequences are identified by the SHA-256 of their file (``pipeline.file_digest``: a resume of
an untouched sequence takes it from the user cache instead of hashing again); the fingerprint
keeps no modification time, so that the table's bytes follow from the sequences' alone. A
sequence with an RTE length or a jump limit of its own (``SequenceInfo.length_m``,
``jump_limit_m``, which win over ``length_m``, ``jump_limit_m``) has it recorded with its
digest; one without has no such key, so that a study of such sequences has the fingerprint it
had before sequences had settings of their own. Likewise ``failures`` is recorded only where
it is not ``trial``, the rule every study had before there was another.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pipeline.errors import ConfigError

VERSION = 1
"""Format of the fingerprint (a change of it refuses every older study)."""

COMPARED = ("adapter", "adapter_options", "space", "seed", "length_m", "penalty_pct",
            "jump_limit_m", "time_limit_s", "startup_trials", "told_lag", "pruning", "fidelity",
            "warm_start", "failures", "sequences")
"""Keys that define a study, in the order differences are named."""

UNRECORDED = {"failures": "trial"}
"""Keys a fingerprint holds only where they differ from this value (a study stored before the
key existed has it)."""


def study_fingerprint(*, adapter: str, adapter_options: Mapping[str, Any],
                      space: list[dict[str, Any]], seed: int, length_m: float,
                      penalty_pct: float, jump_limit_m: float, time_limit_s: float | None,
                      startup_trials: int, told_lag: int, pruning: Mapping[str, Any],
                      sequences: list[tuple[str, str]],
                      fidelity: Mapping[str, Any] | None = None,
                      warm_start: list[dict[str, float]] | None = None,
                      own_lengths_m: Sequence[float | None] = (),
                      own_jump_limits_m: Sequence[float | None] = (),
                      failures: str = "trial") -> dict[str, Any]:
    """The fingerprint (plain JSON data) of a study over ``sequences`` ((name, MCAP path)).

    ``fidelity``: the rungs of successive halving (``trials.halving``), None for whole trials
    (a study stored before the rungs existed has none: whole). ``own_lengths_m``,
    ``own_jump_limits_m``: each sequence's own RTE length and jump limit, None (or () for all)
    where it has none. ``failures``: the rule for a failed sequence (``trials.failures``),
    recorded only where it is not ``trial`` (``UNRECORDED``).
    """
    lengths = list(own_lengths_m) or [None] * len(sequences)
    jumps = list(own_jump_limits_m) or [None] * len(sequences)
    out = {
        "version": VERSION,
        "adapter": adapter,
        "adapter_options": json.loads(json.dumps(dict(adapter_options), sort_keys=True,
                                                  default=str)),
        "space": space,
        "seed": int(seed),
        "length_m": float(length_m),
        "penalty_pct": float(penalty_pct),
        "jump_limit_m": float(jump_limit_m),
        "time_limit_s": None if time_limit_s is None else float(time_limit_s),
        "startup_trials": int(startup_trials),
        "told_lag": int(told_lag),
        "pruning": dict(pruning),
        "fidelity": None if fidelity is None else dict(fidelity),
        "warm_start": list(warm_start or []),
        "sequences": [sequence_digest(name, path, length_m, jump_m) for (name, path), length_m,
                      jump_m in zip(sequences, lengths, jumps, strict=True)],
    }
    return out if failures == UNRECORDED["failures"] else out | {"failures": failures}


def sequence_digest(name: str, path: str | Path, own_length_m: float | None = None,
                    own_jump_limit_m: float | None = None) -> dict[str, Any]:
    """{"name", "sha256", "size"} of a sequence file, and "length_m", "jump_limit_m", its own
    RTE length and jump limit, where it has them."""
    from pipeline.file_digest import sha256_file

    digest: dict[str, Any] = {"name": name, "sha256": sha256_file(path),
                              "size": os.stat(path).st_size}
    own = {"length_m": own_length_m, "jump_limit_m": own_jump_limit_m}
    return digest | {key: float(v) for key, v in own.items() if v is not None}


def check_fingerprint(stored: Mapping[str, Any] | None, current: Mapping[str, Any],
                      where: str) -> None:
    """ConfigError unless ``stored`` (found with the table at ``where``) defines the same
    study as ``current``; the message names every difference."""
    if stored is None or stored.get("version") != VERSION:
        raise ConfigError(f"{where}: holds trials without a study fingerprint of this adaptune "
                          "version; delete it (or use another --out) to start over")
    now = {key: current.get(key, UNRECORDED.get(key)) for key in COMPARED}
    then = {key: stored.get(key, UNRECORDED.get(key)) for key in COMPARED}
    diffs = [_describe(key, now[key], then[key]) for key in COMPARED
             if _comparable(key, now[key]) != _comparable(key, then[key])]
    if diffs:
        raise ConfigError(f"{where}: holds a study with other settings ({'; '.join(diffs)}); "
                          "resume with the same ones, or delete it (or use another --out) to "
                          "start over")


OWN = {"length_m": "RTE length", "jump_limit_m": "jump limit"}
"""A sequence's own settings in its digest, and how a resume's refusal names them."""


def _comparable(key: str, value: Any) -> Any:
    """The part of a value that defines the study (sequences: names, digests and own settings
    only)."""
    if key == "sequences" and isinstance(value, list):
        return [(s.get("name"), s.get("sha256"), *(s.get(k) for k in OWN)) for s in value
                if isinstance(s, dict)]
    return json.dumps(value, sort_keys=True)


def _own(value_m: float | None) -> str:
    """A sequence's own setting as a resume's refusal names it."""
    return "none of its own" if value_m is None else f"{value_m:g} m"


def _describe(key: str, now: Any, stored: Any) -> str:
    if key == "sequences":
        a = {n: rest for n, *rest in _comparable(key, now)}
        b = {n: rest for n, *rest in _comparable(key, stored)}
        if set(a) != set(b):
            return f"sequences {sorted(a)}, stored {sorted(b)}"
        changed = sorted(n for n in a if a[n] != b[n])[0]
        if a[changed][0] == b[changed][0]:
            return "; ".join(f"{what} of sequence {changed} {_own(x)}, stored {_own(y)}"
                             for what, x, y in zip(OWN.values(), a[changed][1:],
                                                   b[changed][1:], strict=True) if x != y)
        return f"content of sequence {changed} changed (sha256 {a[changed][0][:12]}, " \
               f"stored {b[changed][0][:12]})"
    if key == "space":
        return "parameter space differs"
    return f"{key} {json.dumps(now)}, stored {json.dumps(stored)}"
