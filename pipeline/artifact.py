"""The model artifact (``model/``): a folder of ``manifest.json`` and plain ``.npy`` arrays;
its format and its loader (the writer: ``pipeline.surrogates.writer``).

The manifest (schemas/artifact.schema.json) names the algorithm and its parameter space, the
descriptor, the PCA, the surrogate and its scalings, the novelty guard (its distance and
fallback), the training summary, the cross-validation error, the sha256 of every other file
and where the model came from; its own canonical sha256 is stored in it
(``MANIFEST_HASH_KEY``). The selector's runtime settings are not in it (params ``select``,
``pipeline.selection``). No pickle anywhere: loading never runs code from the folder
(docs/design.md, "Formats").

numpy and the standard library at import time: the deployable runtime imports this module.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ArtifactError
from pipeline.npy_files import MAX_ARRAY_BYTES, parse_npy, read_npy_file, read_regular_file

Arrays = dict[str, NDArray[Any]]


@dataclass(frozen=True)
class ArraySpec:
    """What an artifact array must be: its number of dimensions and its kind of numbers
    ('f' float, 'i' integer); the loader checks every array against its spec."""

    ndim: int
    kind: str = "f"


ARTIFACT_KIND = "adaptune.surrogate"
ARTIFACT_SCHEMA = "artifact.schema.json"
ARTIFACT_SCHEMA_VERSION = "2.0"
"""The artifact's own format version (the other formats follow ``schemas.SCHEMA_VERSION``);
readers refuse another major version. 2.0: the selector's runtime settings left the manifest
(params ``select``) and the novelty guard has its own block."""
MANIFEST_NAME = "manifest.json"
"""The file that makes a folder an artifact."""
MANIFEST_HASH_KEY = "manifest_sha256"


def canonical_manifest_hash(manifest: Mapping[str, Any]) -> str:
    """sha256 of the manifest without its own hash, as sorted compact JSON."""
    body = {k: v for k, v in manifest.items() if k != MANIFEST_HASH_KEY}
    return hashlib.sha256(
        json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()


# ---------------------------------------------------------------------------------- reading

COMMON_FILES: dict[str, ArraySpec] = {
    "env.npy": ArraySpec(2),
    "env_frames.npy": ArraySpec(1, "i"),
    "candidates.npy": ArraySpec(2),
    "pca_mean.npy": ArraySpec(1),
    "pca_components.npy": ArraySpec(2),
    "pca_scale.npy": ArraySpec(1),
}
"""The arrays of every artifact, whatever its surrogate (which adds its ``files``)."""
MAX_MANIFEST_BYTES = 64 << 20


def read_manifest(path: Path) -> dict[str, Any]:
    """``path``/manifest.json: a regular file, valid JSON, an adaptune manifest whose own
    checksum matches, of a schema version this code reads. ArtifactError otherwise."""
    mpath = path / MANIFEST_NAME
    if not mpath.exists() and not mpath.is_symlink():
        raise ArtifactError(f"{path}: not a model artifact (no manifest.json)")
    from pipeline.json_yaml import parse_json

    data = read_regular_file(mpath, MAX_MANIFEST_BYTES)
    manifest = parse_json(data, f"{mpath}: damaged manifest", error=ArtifactError)
    if not isinstance(manifest, dict) or manifest.get("kind") != ARTIFACT_KIND:
        raise ArtifactError(f"{mpath}: not an adaptune surrogate manifest")
    if manifest.get(MANIFEST_HASH_KEY) != canonical_manifest_hash(manifest):
        raise ArtifactError(f"{mpath}: manifest checksum mismatch (the manifest was altered)")
    major = str(manifest.get("schema_version", "")).split(".")[0]
    if major != ARTIFACT_SCHEMA_VERSION.split(".")[0]:
        raise ArtifactError(f"{path}: artifact schema version {manifest.get('schema_version')!r}, "
                            f"this adaptune reads {ARTIFACT_SCHEMA_VERSION} (refit the model: "
                            "the surrogate stage)")
    return manifest


def read_arrays(path: Path, manifest: Mapping[str, Any],
                specs: Mapping[str, ArraySpec]) -> Arrays:
    """Every file the manifest lists, read safely (its header and size checked against the
    shape and dtype the manifest declares before its array is read), checksums verified,
    parsed, checked against ``specs`` (each spec'd file must be listed) and finite.
    ArtifactError otherwise."""
    files = manifest.get("files")
    if not isinstance(files, dict):
        raise ArtifactError(f"{path}/manifest.json: no file list")
    missing = [f for f in specs if f not in files]
    if missing:
        raise ArtifactError(f"{path}/manifest.json: does not list {missing[0]}")
    declared = manifest.get("arrays")
    if not isinstance(declared, dict):
        raise ArtifactError(f"{path}/manifest.json: no array shapes ('arrays': an artifact "
                            "written before they were recorded; rebuild it with `adaptune "
                            "surrogate`)")
    arrays: Arrays = {}
    for name, digest in files.items():
        if (not isinstance(name, str) or Path(name).name != name or name in (".", "..")
                or not name.endswith(".npy")):
            raise ArtifactError(f"{path}/manifest.json: file name {name!r} is not a plain "
                                ".npy name")
        fpath = path / name
        data = read_npy_file(fpath, declared.get(name), MAX_ARRAY_BYTES)
        if hashlib.sha256(data).hexdigest() != digest:
            raise ArtifactError(f"{fpath}: sha256 mismatch (file altered or damaged)")
        arrays[name] = parse_npy(data, fpath)
    for name, spec in specs.items():
        arr = arrays[name]
        kinds = "f" if spec.kind == "f" else "iu"
        if arr.ndim != spec.ndim or arr.dtype.kind not in kinds:
            raise ArtifactError(
                f"{path / name}: must be {spec.ndim}-D {'float' if spec.kind == 'f' else 'int'}, "
                f"got {arr.ndim}-D {arr.dtype}")
        if spec.kind == "f" and not np.isfinite(arr).all():
            raise ArtifactError(f"{path / name}: holds values that are not finite")
    return arrays


def check_algorithm_space(manifest: Mapping[str, Any],
                          declared: Sequence[tuple[str, str]] | None) -> None:
    """ValueError unless the manifest's ``parameter_space`` names the parameters its
    ``algorithm`` tunes, in order and of their kinds (``declared``: the adapter's (name, kind)
    pairs; None: an adapter whose options declare them, nothing to check). Its checksum only
    says it was not altered: an algorithm relabelled and re-hashed was a schedule labelled gicp
    with NDT's parameters."""
    if declared is None:
        return
    space = manifest.get("parameter_space") or []
    got = [(s.get("name"), s.get("kind")) for s in space]
    if got != [tuple(d) for d in declared]:
        raise ValueError(f"algorithm {manifest.get('algorithm')!r} tunes {_pairs(declared)}, "
                         f"the parameter_space names {_pairs(got)}")


def _pairs(specs: Sequence[tuple[Any, Any]]) -> str:
    """``[name (kind), ...]`` as text."""
    return "[" + ", ".join(f"{name} ({kind})" for name, kind in specs) + "]"


def _number(value: Any, what: str, low: float | None = None, strict: bool = False) -> float:
    """``value`` as a finite float (> or >= ``low``); ValueError naming ``what`` otherwise."""
    import math

    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, got {value!r}")
    if low is not None and (value <= low if strict else value < low):
        raise ValueError(f"{what} must be {'>' if strict else '>='} {low:g}, got {value!r}")
    return float(value)


def _object(value: Any, what: str) -> Mapping[str, Any]:
    """``value`` when it is a JSON object; ValueError naming ``what`` otherwise."""
    if not isinstance(value, dict):
        raise ValueError(f"{what} must be an object, got {value!r}")
    return value


def validate_values(manifest: Mapping[str, Any]) -> None:
    """The manifest's numbers and names make sense (its checksum only says they were not
    altered): the parameter space, the scalings, the selection settings, the fallback.
    ValueError naming the field and the rule."""
    space = manifest.get("parameter_space")
    if not isinstance(space, list) or not space or not all(isinstance(s, dict) for s in space):
        raise ValueError("parameter_space must be a non-empty list of parameters")
    names = [s.get("name") for s in space]
    if not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
        raise ValueError(f"parameter_space names must be distinct and non-empty, got {names}")
    for s in space:
        name = s["name"]
        low = _number(s.get("low"), f"parameter_space {name}.low")
        high = _number(s.get("high"), f"parameter_space {name}.high")
        if not low < high:
            raise ValueError(f"parameter_space {name}: low must be < high, got "
                             f"(low={low:g}, high={high:g})")
        default = _number(s.get("default"), f"parameter_space {name}.default")
        if not low <= default <= high:
            raise ValueError(f"parameter_space {name}.default {default:g} is outside "
                             f"[{low:g}, {high:g}]")
        if s.get("kind") not in ("float", "int") or not isinstance(s.get("log"), bool):
            raise ValueError(f"parameter_space {name}: kind must be float|int and log a bool")
        if s["log"] and low <= 0:
            raise ValueError(f"parameter_space {name}: a log scale needs low > 0, got {low:g}")
    scaling = _object(manifest.get("scaling"), "scaling")
    environment = _object(scaling.get("environment"), "scaling.environment")
    _number(environment.get("e_scale"), "scaling.environment.e_scale", 0.0, strict=True)
    _number(environment.get("w_e"), "scaling.environment.w_e", 0.0, strict=True)
    _number(_object(scaling.get("parameters"), "scaling.parameters").get("x_scale"),
            "scaling.parameters.x_scale", 0.0, strict=True)
    model = _object(manifest.get("model"), "model")
    if model.get("target") not in ("log", "linear"):
        raise ValueError(f"model.target must be 'log' or 'linear', got {model.get('target')!r}")
    _validate_novelty(manifest.get("novelty"), space)


def _validate_novelty(novelty: Any, space: list[dict[str, Any]]) -> None:
    if not isinstance(novelty, dict):
        raise ValueError("novelty must be an object")
    if novelty.get("distance") is not None:
        _number(novelty["distance"], "novelty.distance", 0.0)
    chosen = novelty.get("fallback_params")
    record = novelty.get("fallback")
    if not isinstance(record, dict):
        raise ValueError(f"novelty.fallback must be an object, got {record!r}")
    if record.get("chosen") == "per_scan" and chosen is None:
        raise ValueError("novelty.fallback 'per_scan' needs novelty.fallback_params "
                         "(the fixed parameters it weighs against the defaults)")
    if chosen is None:
        return
    specs = {s["name"]: s for s in space}
    if not isinstance(chosen, dict) or set(chosen) != set(specs):
        got = sorted(chosen) if isinstance(chosen, dict) else chosen
        raise ValueError(f"novelty.fallback_params must name the parameters "
                         f"{sorted(specs)}, got {got}")
    for name, value in chosen.items():
        v = _number(value, f"novelty.fallback_params.{name}")
        if not specs[name]["low"] <= v <= specs[name]["high"]:
            raise ValueError(f"novelty.fallback_params.{name} = {v:g} is outside "
                             f"[{specs[name]['low']:g}, {specs[name]['high']:g}]")


def validate_arrays(arrays: Arrays, n_params: int, descriptor_size: int) -> None:
    """The common arrays fit together: env (n_env, D), env_frames (n_env,), candidates (C, P)
    in [0, 1], pca_components (D, F), pca_mean and pca_scale (F,) with F the descriptor's size
    and pca_scale > 0. ValueError naming the file."""
    env, comps = arrays["env.npy"], arrays["pca_components.npy"]
    n_env, d = env.shape
    if n_env < 1 or d < 1:
        raise ValueError(f"env.npy: needs at least one frame and one dimension, got {env.shape}")
    if arrays["env_frames.npy"].shape != (n_env,):
        raise ValueError(f"env_frames.npy: shape {arrays['env_frames.npy'].shape}, "
                         f"expected ({n_env},)")
    if comps.shape != (d, descriptor_size):
        raise ValueError(f"pca_components.npy: shape {comps.shape}, expected "
                         f"({d}, {descriptor_size}) (environment, descriptor)")
    for name in ("pca_mean.npy", "pca_scale.npy"):
        if arrays[name].shape != (descriptor_size,):
            raise ValueError(f"{name}: shape {arrays[name].shape}, expected ({descriptor_size},)")
    if not (arrays["pca_scale.npy"] > 0).all():
        raise ValueError("pca_scale.npy: pca_scale must be > 0")
    cands = arrays["candidates.npy"]
    if len(cands) < 1 or cands.shape[1] != n_params:
        raise ValueError(f"candidates.npy: shape {cands.shape}, expected (C >= 1, {n_params})")
    if cands.min() < 0.0 or cands.max() > 1.0:
        raise ValueError("candidates.npy: values must lie in [0, 1] (the unit cube)")
