"""A new surrogate or descriptor is one module plus one registry line (docs/design.md, "Seams").

The module below is written to a temporary folder, outside the package, and registered with one
line each (``SURROGATES[...] = ...``, ``DESCRIPTORS[...] = ...``); nothing else of adaptune is
edited. Both then go the whole way: a descriptor and its PCA on real KITTI scans, the fit with
its cross-validation, the artifact written (its schema takes the new types from the registries)
and verified when loaded, and a selection from a scan.
"""

from __future__ import annotations

import importlib
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers.models import DEFAULTS_FALLBACK, SEQS, kitti_scan

from pipeline.descriptors import DESCRIPTORS, descriptor_from_json, make_descriptor
from pipeline.errors import ArtifactError
from pipeline.odometry.registry import get_adapter
from pipeline.pca import Pca, fit_pca
from pipeline.runtime import Selector, load_model
from pipeline.selection import SelectionSettings
from pipeline.surrogates import SURROGATES
from pipeline.surrogates.fit import fit_surrogate
from pipeline.surrogates.rows import TrainingRows
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.writer import ArtifactInfo, write_artifact

PLUGIN = textwrap.dedent('''
    """A linear surrogate and a range-histogram descriptor: what a user adds."""
    from __future__ import annotations

    from dataclasses import dataclass
    from typing import Any, ClassVar

    import numpy as np

    from pipeline.artifact import ArraySpec
    from pipeline.surrogates.base import Prediction


    def _least_squares(features, t):
        A = np.hstack([features, np.ones((len(features), 1))])
        return np.linalg.lstsq(A, t, rcond=None)[0]


    class LinearRegressor:
        def fit(self, features, t):
            self.coef = _least_squares(features, t)
            return self

        def predict(self, features):
            return np.hstack([features, np.ones((len(features), 1))]) @ self.coef


    @dataclass
    class LinearSurrogate:
        type: ClassVar[str] = "linear"
        risk_aware: ClassVar[bool] = False
        files: ClassVar[dict[str, ArraySpec]] = {"linear_coef.npy": ArraySpec(1)}
        manifest_schema: ClassVar[dict[str, Any]] = {
            "required": ["terms"], "properties": {"terms": {"type": "integer", "minimum": 2}}}
        coef: np.ndarray
        target: str = "log"

        @classmethod
        def fit(cls, training, section):
            return cls(_least_squares(training.features(), training.rows_t), section.target)

        @classmethod
        def regressor(cls, section, n_params):
            return LinearRegressor()

        def predict(self, features):
            return np.hstack([features, np.ones((len(features), 1))]) @ self.coef

        def arrays(self):
            return {"linear_coef.npy": self.coef}

        def to_json(self):
            return {"type": self.type, "terms": len(self.coef), "target": self.target}

        @classmethod
        def from_artifact(cls, model, arrays):
            coef = arrays["linear_coef.npy"]
            width = arrays["env.npy"].shape[1] + arrays["candidates.npy"].shape[1] + 1
            if len(coef) != width:
                raise ValueError(f"linear_coef.npy: {len(coef)} terms, expected {width}")
            return cls(coef, model["target"])

        def search(self, candidates_u, x_scale, options):
            return LinearSearch(self, x_scale)


    class LinearSearch:
        def __init__(self, model, x_scale):
            self.model, self.x_scale = model, x_scale

        def at(self, e_s, env_d2):
            return LinearQuery(self.model, e_s, self.x_scale)


    class LinearQuery:
        rows_searched = 0

        def __init__(self, model, e_s, x_scale):
            self.model, self.e_s, self.x_scale = model, e_s, x_scale

        def predict(self, U):
            feats = np.hstack([np.broadcast_to(self.e_s, (len(U), len(self.e_s))),
                               U * self.x_scale])
            t = self.model.predict(feats)
            return Prediction(t, np.ones(len(t), bool))

        def certified(self, U):
            return self.predict(U).t

        def candidate_values(self, candidates):
            return self.certified(candidates)


    @dataclass(frozen=True)
    class RangeHistogram:
        type: ClassVar[str] = "range_histogram"
        manifest_schema: ClassVar[dict[str, Any]] = {
            "required": ["bins", "max_range_m"],
            "properties": {"bins": {"type": "integer", "minimum": 1},
                           "max_range_m": {"type": "number", "exclusiveMinimum": 0}}}
        bins: int = 8
        max_range_m: float = 80.0

        @property
        def size(self):
            return self.bins

        def describe(self, points_lidar):
            r = np.linalg.norm(np.asarray(points_lidar)[:, :3], axis=1)
            h, _ = np.histogram(r, self.bins, (0.0, self.max_range_m))
            return (h / max(1, h.sum())).astype(np.float32)

        def value_names(self):
            return [f"range_{i}" for i in range(self.bins)]

        def to_json(self):
            return {"type": self.type, "bins": self.bins, "max_range_m": self.max_range_m,
                    "size": self.size}
''')


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> object:
    """The user's module, imported from a temporary folder, each class registered in one line."""
    (tmp_path / "user_plugin.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("user_plugin")
    monkeypatch.setitem(SURROGATES, "linear", module.LinearSurrogate)  # the one registry line
    monkeypatch.setitem(DESCRIPTORS, "range_histogram", module.RangeHistogram)  # and this one
    yield module
    sys.modules.pop("user_plugin", None)


def test_a_new_surrogate_and_descriptor_go_from_fit_to_selection(
        plugin: object, tmp_path: Path, kitti_root: Path) -> None:
    descriptor = make_descriptor("range_histogram", {"bins": 8})
    assert descriptor_from_json(descriptor.to_json()) == descriptor
    scans = {(s, f): kitti_scan(kitti_root, s, f) for s in SEQS for f in range(10)}
    desc = np.stack([descriptor.describe(p) for p in scans.values()])
    pca = fit_pca(desc, 3, list(SEQS))
    pca.descriptor = descriptor.to_json()
    E = pca.transform(desc)
    rng = np.random.default_rng(0)
    trials = rng.random((6, 2))
    rows = TrainingRows(
        np.repeat(E, len(trials), axis=0), np.tile(trials, (len(E), 1)),
        np.exp(rng.normal(0.0, 0.3, len(E) * len(trials))),
        np.repeat([s for s, _ in scans], len(trials)), np.repeat([f for _, f in scans], 6),
        np.tile(np.arange(len(trials)), len(E)))
    space = get_adapter("ndt").space.to_json()
    fitted = fit_surrogate(rows, space, SurrogateSection(model="linear", n_sobol=16,
                                                         cv_max_frames=3))
    assert fitted.surrogate.type == "linear" and fitted.cv["folds"] == len(SEQS)
    out = tmp_path / "model"
    manifest = write_artifact(out, fitted, pca,
                              ArtifactInfo("ndt", space, descriptor, DEFAULTS_FALLBACK))
    assert manifest["model"]["type"] == "linear"
    assert manifest["descriptor"]["type"] == "range_histogram"
    model = load_model(out, "ndt")
    selector = Selector(model, SelectionSettings(refine_iters=0))
    chosen = selector.select(kitti_scan(kitti_root, "04", 5))
    get_adapter("ndt").space.validate(chosen)
    assert selector.last["kept"] in ("", "novel")


def test_the_schema_checks_a_new_type_by_its_own_rules(
        plugin: object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The registered class's ``manifest_schema`` is enforced when the artifact is written, and
    a type no registry knows is refused when it is loaded."""
    bad = plugin.RangeHistogram(bins=1, max_range_m=0.0)  # type: ignore[attr-defined]
    rows_e = np.zeros((4, 1))
    rows = TrainingRows(rows_e, np.full((4, 2), 0.5), np.ones(4), np.array(["a", "a", "b", "b"]),
                        np.array([0, 1, 0, 1]), np.zeros(4, int))
    space = get_adapter("ndt").space.to_json()
    fitted = fit_surrogate(rows, space, SurrogateSection(model="linear", n_sobol=4,
                                                         cv_max_frames=2, novelty_quantile=None))
    pca = Pca(np.zeros(1), np.ones(1), np.eye(1, 1), np.ones(1))
    with pytest.raises(ArtifactError, match="descriptor/max_range_m"):
        write_artifact(tmp_path / "m", fitted, pca,
                       ArtifactInfo("ndt", space, bad, DEFAULTS_FALLBACK))
    assert not (tmp_path / "m").exists()
    good = plugin.RangeHistogram(bins=1)  # type: ignore[attr-defined]
    write_artifact(tmp_path / "m", fitted, pca, ArtifactInfo("ndt", space, good,
                                                              DEFAULTS_FALLBACK))
    monkeypatch.delitem(SURROGATES, "linear")  # the registry line taken away again
    with pytest.raises(ArtifactError, match="unknown surrogate type 'linear'"):
        load_model(tmp_path / "m")
