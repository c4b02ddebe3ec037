"""The model artifact (``model/``): a folder of ``manifest.json`` and plain ``.npy`` arrays.

The manifest (schemas/artifact.schema.json) names the algorithm and its parameter space, the
descriptor, the PCA, the surrogate and its scalings, the selection settings, the training
summary, the cross-validation error, the sha256 of every other file and where the model came
from; its own canonical sha256 is stored in it (``MANIFEST_HASH_KEY``). No pickle anywhere:
loading never runs code from the folder (docs/design.md, "The artifact").

numpy and the standard library at import time: the deployable runtime imports this module.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ArtifactError

if TYPE_CHECKING:
    from pipeline.descriptor import DescriptorConfig
    from pipeline.pca import Pca
    from pipeline.surrogates.fit import FittedSurrogate

ARTIFACT_KIND = "adaptune.surrogate"
ARTIFACT_SCHEMA = "artifact.schema.json"
MANIFEST_HASH_KEY = "manifest_sha256"


def canonical_manifest_hash(manifest: Mapping[str, Any]) -> str:
    """sha256 of the manifest without its own hash, as sorted compact JSON."""
    body = {k: v for k, v in manifest.items() if k != MANIFEST_HASH_KEY}
    return hashlib.sha256(
        json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()


def save_npy(path: Path, arr: NDArray[Any]) -> str:
    """np.save without pickle; returns the sha256 of the written file."""
    np.save(path, np.ascontiguousarray(arr), allow_pickle=False)
    return hashlib.sha256(path.read_bytes()).hexdigest()


@dataclass
class ArtifactInfo:
    """What the manifest says besides the arrays."""

    algorithm: str
    space: list[dict[str, Any]]
    descriptor: DescriptorConfig
    selection: Mapping[str, Any]
    inputs: Mapping[str, str] = field(default_factory=dict)


def write_artifact(
    out: str | Path,
    fitted: FittedSurrogate,
    pca: Pca,
    info: ArtifactInfo,
    repo: str | Path | None = None,
) -> dict[str, Any]:
    """Write ``out``/ (manifest.json + .npy arrays) atomically; returns the manifest.

    The manifest is validated against schemas/artifact.schema.json before the rename.
    """
    from pipeline.io_utils import atomic_dir
    from pipeline.provenance import provenance
    from schemas import SCHEMA_VERSION

    arrays = {
        "env.npy": fitted.env,
        "env_offsets.npy": fitted.env_offsets,
        "env_frames.npy": fitted.env_frames,
        "rows_x.npy": fitted.rows_x,
        "rows_t.npy": fitted.rows_t,
        "candidates.npy": fitted.candidates_u,
        "pca_mean.npy": pca.mean,
        "pca_components.npy": pca.components,
        "pca_scale.npy": pca.scale,
    }
    with atomic_dir(out) as tmp:
        files = {name: save_npy(tmp / name, arr) for name, arr in arrays.items()}
        manifest = {
            "schema_version": SCHEMA_VERSION,
            "kind": ARTIFACT_KIND,
            "algorithm": info.algorithm,
            "parameter_space": info.space,
            "descriptor": info.descriptor.to_json(),
            "pca": pca.to_json(),
            "model": {
                "type": "knn",
                "k": fitted.settings.k,
                "weights": "uniform",
                "metric": "euclidean",
                "target": fitted.settings.target,
            },
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
            "selection": {**info.selection, "novelty_distance": fitted.novelty_distance},
            "training": {**fitted.summary, "env_sequences": fitted.env_sequences},
            "cross_validation": fitted.cv,
            "files": files,
            "provenance": provenance(repo, info.inputs),
        }
        validate_manifest(manifest)
        manifest[MANIFEST_HASH_KEY] = canonical_manifest_hash(manifest)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2), encoding="utf-8")
    return manifest


def validate_manifest(manifest: dict[str, Any]) -> None:
    """ArtifactError unless ``manifest`` follows schemas/artifact.schema.json."""
    import jsonschema

    from schemas import read_text

    try:
        jsonschema.validate(manifest, json.loads(read_text(ARTIFACT_SCHEMA)))
    except jsonschema.ValidationError as exc:
        path = "/".join(str(p) for p in exc.absolute_path) or "(root)"
        raise ArtifactError(f"manifest.json: {path}: {exc.message}") from None
