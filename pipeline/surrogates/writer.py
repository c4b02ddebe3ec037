"""Writing the model artifact (``model/``; the format and the loader: ``pipeline.artifact``).

The manifest is validated against schemas/artifact.schema.json before the folder is renamed
into place. The schema's lists of surrogate and descriptor types, and what each type's block
holds, come from the registries (``artifact_schema``: each class's ``manifest_schema``), so a
new surrogate or descriptor is one module and one registry line.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.artifact import (
    ARTIFACT_KIND,
    ARTIFACT_SCHEMA,
    ARTIFACT_SCHEMA_VERSION,
    MANIFEST_HASH_KEY,
    MANIFEST_NAME,
    canonical_manifest_hash,
)
from pipeline.errors import ArtifactError
from pipeline.npy_files import npy_declaration, save_npy

if TYPE_CHECKING:
    from pipeline.descriptors import Descriptor
    from pipeline.pca import Pca
    from pipeline.surrogates.fitted import FittedSurrogate


@dataclass
class ArtifactInfo:
    """What the manifest says besides the fitted model: the algorithm, its parameter space, the
    descriptor, the novelty fallback (``pipeline.surrogates.novelty``: its record and, when it
    chose them, the parameters) and the inputs it came from."""

    algorithm: str
    space: list[dict[str, Any]]
    descriptor: Descriptor
    fallback: Mapping[str, Any]
    fallback_params: Mapping[str, float] | None = None
    inputs: Mapping[str, str] = field(default_factory=dict)


def write_artifact(
    out: str | Path,
    fitted: FittedSurrogate,
    pca: Pca,
    info: ArtifactInfo,
) -> dict[str, Any]:
    """Write ``out``/ (manifest.json + .npy arrays) atomically; returns the manifest."""
    from pipeline.io_utils import atomic_dir

    arrays = {
        "env.npy": fitted.env,
        "env_frames.npy": fitted.env_frames,
        "candidates.npy": fitted.candidates_u,
        "pca_mean.npy": pca.mean,
        "pca_components.npy": pca.components,
        "pca_scale.npy": pca.scale,
        **fitted.surrogate.arrays(),
    }
    with atomic_dir(out) as tmp:
        files = {name: save_npy(tmp / name, arr) for name, arr in arrays.items()}
        shapes = {name: npy_declaration(arr) for name, arr in arrays.items()}
        manifest = manifest_of(fitted, pca, info, files, shapes)
        validate_manifest(manifest)
        manifest[MANIFEST_HASH_KEY] = canonical_manifest_hash(manifest)
        (tmp / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2), encoding="utf-8")
    return manifest


def manifest_of(fitted: FittedSurrogate, pca: Pca, info: ArtifactInfo,
                files: Mapping[str, str], shapes: Mapping[str, Any]) -> dict[str, Any]:
    """The manifest (without its own hash) of an artifact whose arrays hash to ``files`` and
    have the shapes and dtypes ``shapes`` (``npy_declaration``); its provenance is what its
    inputs held (``pipeline.provenance.content``: the git and DVC state go to the stage's
    record)."""
    from pipeline.provenance import content

    novelty: dict[str, Any] = {"distance": fitted.novelty_distance,
                               "fallback": dict(info.fallback)}
    if info.fallback_params is not None:
        novelty["fallback_params"] = dict(info.fallback_params)
    return {
        "schema_version": ARTIFACT_SCHEMA_VERSION,
        "kind": ARTIFACT_KIND,
        "algorithm": info.algorithm,
        "parameter_space": info.space,
        "descriptor": info.descriptor.to_json(),
        "pca": pca.to_json(),
        "model": fitted.surrogate.to_json(),
        "scaling": {
            "environment": {
                "w_e": fitted.settings.w_e,
                "e_scale": fitted.e_scale,
                "formula": "E_s = w_e * E / e_scale",
            },
            "parameters": {
                "w_x": fitted.settings.w_x,
                "x_scale": fitted.x_scale,
                "formula": "X_s = x_scale * to_unit(x), x_scale = w_x*sqrt(12)",
            },
            "target": fitted.settings.target,
        },
        "novelty": novelty,
        "training": {**fitted.summary, "env_sequences": fitted.env_sequences},
        "cross_validation": fitted.cv,
        "files": dict(files),
        "arrays": dict(shapes),
        "provenance": content(info.inputs),
    }


def artifact_schema() -> dict[str, Any]:
    """schemas/artifact.schema.json with the registered surrogate and descriptor types: each
    block's ``type`` must name one, and then follow that class's ``manifest_schema``."""
    from pipeline.descriptors import DESCRIPTORS
    from pipeline.surrogates import SURROGATES
    from schemas import read_text

    schema: dict[str, Any] = json.loads(read_text(ARTIFACT_SCHEMA))
    props = schema["properties"]
    for block, registry in (("model", SURROGATES), ("descriptor", DESCRIPTORS)):
        props[block]["properties"]["type"] = {"enum": list(registry)}
        props[block]["allOf"] = [
            {"if": {"properties": {"type": {"const": name}}},
             "then": getattr(cls, "manifest_schema", {})}
            for name, cls in registry.items()]
    return schema


def validate_manifest(manifest: dict[str, Any]) -> None:
    """ArtifactError unless ``manifest`` follows ``artifact_schema``."""
    import jsonschema

    try:
        jsonschema.validate(manifest, artifact_schema())
    except jsonschema.ValidationError as exc:
        path = "/".join(str(p) for p in exc.absolute_path) or "(root)"
        raise ArtifactError(f"manifest.json: {path}: {exc.message}") from None
