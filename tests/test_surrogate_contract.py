"""The contract every registered surrogate keeps (pipeline/surrogates/base.py), run over the
registry the way optuna runs one suite over every sampler: fit, artifact round trip, runtime
queries that agree with the fitted model, cross-validation, determinism, a refused artifact."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from helpers.models import DEFAULTS_FALLBACK, SEL, kitti_scan, synthetic_rows

from pipeline.artifact import canonical_manifest_hash
from pipeline.descriptors import NdtHistogram
from pipeline.errors import ArtifactError, ConfigError
from pipeline.odometry.registry import get_adapter
from pipeline.runtime import Selector, load_model
from pipeline.surrogates import SURROGATES
from pipeline.surrogates.base import Query, Surrogate
from pipeline.surrogates.fit import fit_surrogate
from pipeline.surrogates.fitted import FittedSurrogate
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.writer import ArtifactInfo, artifact_schema, write_artifact

NAMES = list(SURROGATES)


def section(name: str) -> SurrogateSection:
    return SurrogateSection(model=name, n_sobol=64, cv_max_frames=4,
                            forest={"trees": 8, "max_samples": 400})


@pytest.fixture(scope="module", params=NAMES)
def fitted(request: pytest.FixtureRequest, kitti_root: Path) -> FittedSurrogate:
    rows, _ = synthetic_rows(kitti_root, trials=12)
    return fit_surrogate(rows, get_adapter("ndt").space.to_json(), section(request.param))


@pytest.fixture(scope="module")
def model_dir(fitted: FittedSurrogate, kitti_root: Path,
              tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, pca = synthetic_rows(kitti_root, trials=12)
    out = tmp_path_factory.mktemp(fitted.settings.model) / "model"
    space = get_adapter("ndt").space.to_json()
    write_artifact(out, fitted, pca, ArtifactInfo("ndt", space, NdtHistogram(), DEFAULTS_FALLBACK))
    return out


def test_the_registry_and_the_manifest_schema_agree() -> None:
    schema = artifact_schema()
    assert schema["properties"]["model"]["properties"]["type"]["enum"] == NAMES
    assert NAMES[0] == "knn" and SurrogateSection().model == "knn"  # the default
    for name, cls in SURROGATES.items():
        assert cls.type == name and cls.files and all(f.endswith(".npy") for f in cls.files)


def test_fit_gives_a_surrogate_of_its_type(fitted: FittedSurrogate) -> None:
    s = fitted.surrogate
    assert isinstance(s, Surrogate) and s.type == fitted.settings.model
    assert set(s.arrays()) == set(s.files)
    assert s.to_json()["type"] == s.type and s.to_json()["target"] == "log"


def test_the_artifact_round_trip_keeps_every_array(fitted: FittedSurrogate,
                                                   model_dir: Path) -> None:
    manifest = json.loads((model_dir / "manifest.json").read_text())
    jsonschema.validate(manifest, artifact_schema())
    assert manifest["model"] == fitted.surrogate.to_json()
    model = load_model(model_dir)
    assert type(model.surrogate) is type(fitted.surrogate)
    for name, arr in fitted.surrogate.arrays().items():
        np.testing.assert_array_equal(model.surrogate.arrays()[name], arr)


def test_runtime_queries_agree_with_the_fitted_model(fitted: FittedSurrogate,
                                                     model_dir: Path) -> None:
    model = load_model(model_dir)
    sel = Selector(model, SEL.replace(hysteresis=0.0, refine_iters=0))
    U = np.vstack([sel.candidates, np.random.default_rng(5).random((20, 2))])
    for g in (0, 7, len(model.env) - 1):
        e_s = model.env[g] + 0.01
        q = sel.neighbourhood(e_s)
        assert isinstance(q, Query)
        pred = q.predict(U)
        want = fitted.surrogate.predict(np.hstack([np.repeat(e_s[None], len(U), 0),
                                                   U * model.x_scale]))
        assert pred.exact.any()
        np.testing.assert_allclose(pred.t[pred.exact], want[pred.exact], rtol=1e-12)
        cert = q.certified(U)
        np.testing.assert_allclose(cert[pred.exact], want[pred.exact], rtol=1e-12)
        cand = q.candidate_values(sel.candidates)
        ok = np.isfinite(cand)
        np.testing.assert_allclose(cand[ok], want[: len(sel.candidates)][ok], rtol=1e-12)


def test_risk_is_weighed_or_refused(fitted: FittedSurrogate, model_dir: Path) -> None:
    """``select.risk``: a risk-aware surrogate adds risk * the neighbours' spread to every
    value; any other refuses risk > 0 in the selector, naming both."""
    model = load_model(model_dir)
    name = fitted.settings.model
    if not SURROGATES[name].risk_aware:
        rule = re.escape(f"risk > 0 needs model knn, got (model={name}, risk=0.5)")
        with pytest.raises(ConfigError, match=f"^select.{rule}$"):
            Selector(model, SEL.replace(risk=0.5))
        assert Selector(model, SEL.replace(risk=0.0)).settings.risk == 0.0
        return
    plain, wary = Selector(model, SEL.replace(risk=0.0)), Selector(model, SEL.replace(risk=0.5))
    for g in (0, 7, len(model.env) - 1):
        e_s = model.env[g] + 0.01
        p = plain.neighbourhood(e_s).candidate_values(plain.candidates)
        w = wary.neighbourhood(e_s).candidate_values(wary.candidates)
        ok = np.isfinite(p) & np.isfinite(w)
        assert ok.any() and (w[ok] >= p[ok]).all() and (w[ok] > p[ok]).any()


def test_selection_stays_in_range(model_dir: Path, kitti_root: Path) -> None:
    model = load_model(model_dir)
    space = get_adapter("ndt").space
    sel = Selector(model, SEL)
    for seq, frame in (("01", 2), ("10", 8)):
        params = sel.select(kitti_scan(kitti_root, seq, frame))
        assert space.validate(params) == params
        assert sel.last["kept"] in ("", "hysteresis", "novel")


def test_cross_validation_is_leave_one_sequence_out(fitted: FittedSurrogate) -> None:
    cv = fitted.cv
    assert cv["folds"] == 4 and 0 < cv["mae"] <= cv["rmse"]
    assert cv["regret_mean"] >= 0 and cv["y_chosen_mean"] >= cv["y_oracle_mean"]


def test_fitting_is_deterministic(fitted: FittedSurrogate, kitti_root: Path) -> None:
    rows, _ = synthetic_rows(kitti_root, trials=12)
    again = fit_surrogate(rows, get_adapter("ndt").space.to_json(), fitted.settings)
    for name, arr in fitted.surrogate.arrays().items():
        np.testing.assert_array_equal(again.surrogate.arrays()[name], arr)
    assert again.cv == fitted.cv


def test_a_missing_surrogate_file_is_refused(fitted: FittedSurrogate, model_dir: Path,
                                             tmp_path: Path) -> None:
    for name in fitted.surrogate.files:
        bad = shutil.copytree(model_dir, tmp_path / name)
        manifest = json.loads((bad / "manifest.json").read_text())
        del manifest["files"][name]
        manifest["manifest_sha256"] = canonical_manifest_hash(manifest)
        (bad / "manifest.json").write_text(json.dumps(manifest))
        with pytest.raises(ArtifactError, match=f"does not list {name}"):
            load_model(bad)
