"""The environment E of a frame: PCA of its descriptor (docs/design.md, "Environment").

E = ((h - mean) / scale) @ components.T with h = sqrt(d) of the descriptor d (the Hellinger
transform: Euclidean distances of sqrt-histograms are Hellinger distances, and the few dominant
bins no longer swamp the rare ones); centred by the training mean; divided by one global scale
(the RMS of the centred training features, stored per value as ``scale``, all equal) -- a
per-value standardisation was rejected because values that are nearly always zero (e.g. oblique
lines at 27-30 m) would be blown up to unit variance; then projected on the top ``dim`` right
singular vectors (numpy SVD) of the training frames only.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.json_yaml import parse_json

PCA_FILES = ("mean.npy", "components.npy", "scale.npy")


@dataclass
class Pca:
    """E = ((sqrt(d) - mean) / scale) @ components.T; mean, scale (F,), components (D, F)."""

    mean: NDArray[np.float64]
    scale: NDArray[np.float64]
    components: NDArray[np.float64]
    explained_variance_ratio: NDArray[np.float64]
    n_train_frames: int = 0
    train_sequences: list[str] = field(default_factory=list)
    descriptor: dict[str, Any] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return int(self.components.shape[0])

    def transform(self, descriptors: NDArray[np.floating]) -> NDArray[np.float64]:
        """(N, F) descriptors -> (N, D) environment values."""
        h = np.sqrt(np.maximum(np.asarray(descriptors, np.float64), 0.0))
        return ((h - self.mean) / self.scale) @ self.components.T

    def to_json(self) -> dict[str, Any]:
        return {
            "transform": "hellinger_sqrt",
            "dim": self.dim,
            "features": int(self.mean.shape[0]),
            "n_train_frames": self.n_train_frames,
            "train_sequences": self.train_sequences,
            "explained_variance_ratio": [float(v) for v in self.explained_variance_ratio],
            "descriptor": dict(self.descriptor),
        }

    def save(self, folder: str | Path) -> None:
        """Write mean.npy, components.npy, scale.npy and pca.json (with sha256) into ``folder``,
        atomically (a temp folder renamed onto ``folder``)."""
        from pipeline.io_utils import atomic_dir
        from pipeline.npy_files import save_npy

        arrays = {"mean.npy": self.mean, "components.npy": self.components, "scale.npy": self.scale}
        with atomic_dir(folder) as tmp:
            meta = self.to_json()
            meta["files"] = {name: save_npy(tmp / name, arr) for name, arr in arrays.items()}
            (tmp / "pca.json").write_text(json.dumps(meta, indent=2), encoding="utf-8")

    @classmethod
    def load(cls, folder: str | Path) -> Pca:
        """Read a folder written by ``save``; InputError when files are missing or altered."""
        from pipeline.errors import ArtifactError
        from pipeline.io_utils import read_input_text
        from pipeline.npy_files import MAX_ARRAY_BYTES, parse_npy, read_regular_file

        folder = Path(folder)
        try:
            meta = parse_json(read_input_text(folder / "pca.json", "PCA file", strict=True),
                              str(folder / "pca.json"))
            arr = {}
            for name in PCA_FILES:
                data = read_regular_file(folder / name, MAX_ARRAY_BYTES)
                if hashlib.sha256(data).hexdigest() != meta["files"][name]:
                    raise InputError(f"{folder / name}: sha256 does not match pca.json")
                arr[name] = parse_npy(data, folder / name)
        except (OSError, KeyError, TypeError, ValueError, ArtifactError) as exc:
            raise InputError(f"{folder}: not a PCA folder ({type(exc).__name__}: {exc})") from None
        return cls(
            arr["mean.npy"],
            arr["scale.npy"],
            arr["components.npy"],
            np.asarray(meta["explained_variance_ratio"]),
            int(meta["n_train_frames"]),
            list(meta["train_sequences"]),
            dict(meta.get("descriptor") or {}),
        )


def fit_pca(
    descriptors: NDArray[np.floating], dim: int, train_sequences: Sequence[str] = ()
) -> Pca:
    """PCA of (N, F) training descriptors to ``dim`` components (module docstring)."""
    d = np.asarray(descriptors, np.float64)
    if d.ndim != 2 or len(d) < 2:
        raise InputError(f"PCA needs at least 2 training frames, got {len(d)}")
    if dim > min(d.shape):
        raise ConfigError(
            f"descriptors.pca_dim must be <= min(frames, features) = {min(d.shape)}, got {dim}"
        )
    h = np.sqrt(np.maximum(d, 0.0))
    mean = h.mean(axis=0)
    centred = h - mean
    rms = float(np.sqrt(np.mean(centred**2))) or 1.0
    _, sv, vt = np.linalg.svd(centred / rms, full_matrices=False)
    var = sv**2
    comps = vt[:dim]
    # sign convention: the largest |loading| of every component is positive (deterministic)
    signs = np.sign(comps[np.arange(dim), np.argmax(np.abs(comps), axis=1)])
    comps = comps * np.where(signs == 0, 1.0, signs)[:, None]
    return Pca(
        mean, np.full(d.shape[1], rms), comps, var[:dim] / var.sum(), len(d), list(train_sequences)
    )
