"""PCA (pipeline/pca.py), the kNN surrogate, its cross-validation (pipeline/surrogates/), the
artifact (pipeline/artifact.py), and the `descriptors` / `surrogate` stages. Environments come
from real KITTI scans."""

from __future__ import annotations

import json
from pathlib import Path

import duckdb
import jsonschema
import numpy as np
import pyarrow as pa
import pytest
from click.testing import CliRunner
from helpers.models import (
    SEQS,
    build_model,
    kitti_descriptors,
    kitti_scan,
    synthetic_rows,
    write_tiny_sequence,
)

from pipeline.descriptors.ndt_histogram import describe
from pipeline.errors import ConfigError, InputError
from pipeline.odometry.registry import get_adapter
from pipeline.pca import Pca, fit_pca
from pipeline.runtime import load_model
from pipeline.surrogates.fit import fit_surrogate
from pipeline.surrogates.novelty import choose_fallback, novelty_fallback, read_fallback_evidence
from pipeline.surrogates.rows import TrainingRows
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.writer import artifact_schema
from stages.cli import main


def test_pca_fit_on_training_frames_only(kitti_root: Path) -> None:
    names, _, desc = kitti_descriptors(kitti_root)
    train = names != "10"
    pca = fit_pca(desc[train], 10, ["01", "04", "06"])
    E = pca.transform(desc[train])
    assert E.shape == (30, 10)
    np.testing.assert_allclose(E.mean(0), 0.0, atol=1e-9)  # centred on the training frames
    assert np.all(np.diff(E.var(0)) <= 1e-12)  # components by decreasing variance
    assert 0.5 < pca.explained_variance_ratio.sum() <= 1.0
    other = fit_pca(desc, 10)
    assert not np.allclose(other.mean, pca.mean)  # the held-out frames changed nothing above


def test_artifact_round_trip(tmp_path: Path, kitti_root: Path) -> None:
    model_dir = build_model(tmp_path / "model", kitti_root)
    manifest = json.loads((model_dir / "manifest.json").read_text())
    jsonschema.validate(manifest, artifact_schema())
    assert manifest["algorithm"] == "ndt" and manifest["model"]["k"] == 20
    assert set(manifest["files"]) == {p.name for p in model_dir.iterdir()} - {"manifest.json"}
    assert manifest["provenance"] == {"inputs": {}, "inputs_sha256": {}}  # no git state
    assert not any(p.suffix in (".pkl", ".joblib") for p in model_dir.iterdir())
    model = load_model(model_dir, expected_algorithm="ndt")
    assert model.env.shape == (40, 10) and model.surrogate.rows_x.shape == (40 * 24, 2)
    # the runtime's environment of a scan = the library's PCA of its descriptor, scaled
    _, pca = synthetic_rows(kitti_root)
    scan = kitti_scan(kitti_root, "04", 3)
    e_lib = pca.transform(describe(scan)[None])[0] * model.e_factor
    np.testing.assert_allclose(model.environment(scan), e_lib, rtol=1e-6, atol=1e-9)
    # the stored training environment of frame 04/3 is that same vector
    g = int(
        np.flatnonzero(
            (np.array(manifest["training"]["env_sequences"]) == "04")
            & (np.load(model_dir / "env_frames.npy") == 3)
        )[0]
    )
    np.testing.assert_allclose(model.env[g], e_lib, rtol=1e-5, atol=1e-6)


def test_cross_validation_is_leave_one_sequence_out(tmp_path: Path, kitti_root: Path) -> None:
    rows, _ = synthetic_rows(kitti_root)
    fitted = fit_surrogate(
        rows, get_adapter("ndt").space.to_json(), SurrogateSection(n_sobol=64, cv_max_frames=10)
    )
    cv = fitted.cv
    assert cv["folds"] == 4 and set(cv["per_sequence"]) == set(SEQS)
    assert 0 < cv["mae"] <= cv["rmse"]
    assert cv["regret_mean"] >= 0 and cv["y_chosen_mean"] >= cv["y_oracle_mean"]
    # the surrogate beats picking trials at random in the held-out sequences
    assert cv["y_chosen_mean"] < rows.y.mean()


def test_the_rank_gap_is_the_median_spread_of_a_frames_trials(kitti_root: Path) -> None:
    """rank_gap_median: over every held-out frame, the worst trial's y there minus the best's,
    their median (every frame held out once with cv_max_frames above the frames)."""
    rows, _ = synthetic_rows(kitti_root)
    fitted = fit_surrogate(rows, get_adapter("ndt").space.to_json(),
                           SurrogateSection(n_sobol=0, cv_max_frames=1000))
    gaps = [rows.y[sel].max() - rows.y[sel].min()
            for seq in np.unique(rows.sequences) for f in np.unique(rows.frames)
            if (sel := (rows.sequences == seq) & (rows.frames == f)).sum() > 1]
    assert len(gaps) == 40
    assert fitted.cv["rank_gap_median"] == pytest.approx(np.median(gaps), rel=1e-12)


def test_novelty_distance_is_the_leave_one_sequence_out_quantile(kitti_root: Path) -> None:
    rows, _ = synthetic_rows(kitti_root)
    space = get_adapter("ndt").space.to_json()
    fitted = fit_surrogate(rows, space, SurrogateSection(n_sobol=0, cv_max_frames=2))
    seqs = np.array(fitted.env_sequences)
    d = np.linalg.norm(fitted.env[:, None] - fitted.env[None], axis=2)
    d[seqs[:, None] == seqs[None]] = np.inf  # only frames of other sequences
    nearest = d.min(axis=1)
    assert fitted.novelty_distance == pytest.approx(nearest.max(), rel=1e-12)  # default q = 1
    q90 = fit_surrogate(rows, space, SurrogateSection(n_sobol=0, cv_max_frames=2,
                                                       novelty_quantile=0.9))
    assert q90.novelty_distance == pytest.approx(np.quantile(nearest, 0.9), rel=1e-12)
    assert 0 < q90.novelty_distance < fitted.novelty_distance
    off = fit_surrogate(rows, space, SurrogateSection(n_sobol=0, cv_max_frames=2,
                                                       novelty_quantile=None))
    assert off.novelty_distance is None


def test_descriptors_stage(tmp_path: Path, kitti_root: Path) -> None:
    seq_dir = tmp_path / "sequences"
    seq_dir.mkdir()
    for s in ("04", "06", "10"):
        write_tiny_sequence(seq_dir / f"k{s}.mcap", kitti_root, s)
    (seq_dir / "index.json").write_text(
        json.dumps({"train": ["k04", "k06"], "validation": ["k10"]})
    )
    params = tmp_path / "params.yaml"
    params.write_text("descriptors:\n  pca_dim: 4\n  workers: 1\n")
    out, env, pca_dir = tmp_path / "d.parquet", tmp_path / "e.parquet", tmp_path / "pca"
    res = CliRunner().invoke(
        main,
        [
            "descriptors",
            "--params",
            str(params),
            "--sequences",
            str(seq_dir),
            "--out",
            str(out),
            "--environment",
            str(env),
            "--pca",
            str(pca_dir),
        ],
    )
    assert res.exit_code == 0, res.output
    con = duckdb.connect()
    d = con.execute(f"SELECT * FROM '{out}' ORDER BY sequence, frame").fetchnumpy()
    e = con.execute(f"SELECT * FROM '{env}' ORDER BY sequence, frame").fetchnumpy()
    assert len(d["frame"]) == 12 and len(e["e3"]) == 12 and "e4" not in e
    vals = np.column_stack([d[f"d{i}"] for i in range(90)])
    np.testing.assert_allclose(vals.sum(1), 1.0, rtol=1e-5)
    pca = Pca.load(pca_dir)
    assert pca.train_sequences == ["k04", "k06"] and pca.n_train_frames == 8
    E = np.column_stack([e[f"e{i}"] for i in range(4)])
    np.testing.assert_allclose(E, pca.transform(vals), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(E[:8].mean(0), 0.0, atol=1e-5)  # centred on train frames only


def test_descriptors_stage_bad_index(tmp_path: Path) -> None:
    seq_dir = tmp_path / "sequences"
    seq_dir.mkdir()
    (seq_dir / "index.json").write_text(json.dumps({"train": ["missing"]}))
    out = tmp_path / "d.parquet"
    res = CliRunner().invoke(
        main,
        [
            "descriptors",
            "--params",
            str(tmp_path / "none.yaml"),
            "--sequences",
            str(seq_dir),
            "--out",
            str(out),
            "--environment",
            str(tmp_path / "e.parquet"),
            "--pca",
            str(tmp_path / "pca"),
        ],
    )
    assert res.exit_code == 1
    assert "no such params file" in res.output or "missing" in res.output
    assert not out.exists()


def make_db(path: Path, rows: TrainingRows, algorithm: str = "ndt") -> None:
    """A results database holding the surrogate_rows relation of the contract."""
    names = get_adapter(algorithm).space.names
    space = get_adapter(algorithm).space
    X = np.stack([[space.from_unit(u)[n] for n in names] for u in rows.U])
    con = duckdb.connect(str(path))
    cols = {
        "algorithm": np.full(len(rows.y), algorithm),
        "sequence": rows.sequences,
        "trial": rows.trials,
        "frame": rows.frames,
        **{f"e{i}": rows.E[:, i] for i in range(rows.E.shape[1])},
        **{f"p_{n}": X[:, j] for j, n in enumerate(names)},
        "y": rows.y,
    }
    con.from_arrow(pa.table(cols)).create("surrogate_rows")
    con.close()


def test_surrogate_stage(tmp_path: Path, kitti_root: Path) -> None:
    rows, pca = synthetic_rows(kitti_root, trials=8)
    db = tmp_path / "r.duckdb"
    make_db(db, rows)
    pca.save(tmp_path / "pca")
    params = tmp_path / "params.yaml"
    params.write_text("surrogate:\n  n_sobol: 32\n  cv_max_frames: 3\n")
    out, metrics = tmp_path / "model", tmp_path / "metrics.json"
    res = CliRunner().invoke(
        main,
        [
            "surrogate",
            "--params",
            str(params),
            "--db",
            str(db),
            "--pca",
            str(tmp_path / "pca"),
            "--out",
            str(out),
            "--metrics",
            str(metrics),
            "--record",
            str(tmp_path / "record.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    model = load_model(out, "ndt")
    assert model.manifest["training"]["rows"] == 40 * 8
    # no trials tables in this database: no joint study to compare, the defaults stay
    assert model.novelty_fallback["chosen"] == "defaults"
    assert model.fallback() == model.defaults()
    record = json.loads((tmp_path / "record.json").read_text())
    assert (record["algorithm"], record["folds"]) == ("ndt", 4)  # bookkeeping: not a metric
    figures = json.loads(metrics.read_text())
    assert "folds" not in figures and figures["mae"] > 0
    assert set(figures["per_sequence"]) == set(record["per_sequence"])
    # an algorithm the database does not have: one line, exit 1, no new artifact
    res = CliRunner().invoke(
        main,
        [
            "surrogate",
            "--params",
            str(params),
            "--db",
            str(db),
            "--pca",
            str(tmp_path / "pca"),
            "--out",
            str(tmp_path / "m2"),
            "--algorithm",
            "gicp",
        ],
    )
    assert res.exit_code == 1 and "no surrogate rows for algorithm 'gicp'" in res.output
    assert not (tmp_path / "m2").exists()
    # the fixed parameters as fallback, but no joint study in the database: one line, exit 1
    params.write_text("surrogate:\n  n_sobol: 32\n  cv_max_frames: 3\n  novelty_fallback: fixed\n")
    args = ["surrogate", "--params", str(params), "--db", str(db), "--pca", str(tmp_path / "pca"),
            "--out", str(tmp_path / "m3")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and "needs the joint study" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "m3").exists()


def fallback_db(path: Path, fixed_rte: dict[str, float], default_rte: dict[str, float]) -> None:
    """A results database with per-sequence studies (trial 0 = the NDT defaults, trial 1 = other
    parameters) and a joint study whose best trial (2) scores ``fixed_rte`` per sequence."""
    con = duckdb.connect(str(path))
    con.execute(
        "CREATE TABLE trials (study VARCHAR, algorithm VARCHAR, sequence VARCHAR, trial INTEGER,"
        " status VARCHAR, objective DOUBLE, params_json VARCHAR)"
    )
    con.execute(
        "CREATE TABLE rte_frames (study VARCHAR, algorithm VARCHAR, sequence VARCHAR,"
        " trial INTEGER, frame INTEGER, t_err_pct DOUBLE)"
    )
    defaults = json.dumps(get_adapter("ndt").space.defaults())
    other = json.dumps({"resolution": 1.5, "keyframe_interval": 9.0})
    for seq, y in default_rte.items():
        con.execute("INSERT INTO trials VALUES ('trials', 'ndt', ?, 0, 'ok', ?, ?)",
                    [seq, y, defaults])
        con.execute("INSERT INTO trials VALUES ('trials', 'ndt', ?, 1, 'ok', 0.01, ?)",
                    [seq, other])
    joint = {2: (0.5, {"resolution": 2.5, "keyframe_interval": 6.0}),
             3: (0.9, {"resolution": 3.0, "keyframe_interval": 1.0})}
    for trial, (objective, params) in joint.items():
        con.execute("INSERT INTO trials VALUES ('fixed', 'ndt', '__joint__', ?, 'ok', ?, ?)",
                    [trial, objective, json.dumps(params)])
        for seq, y in fixed_rte.items():  # two frames each, mean y (trial 3: worse)
            for frame, dy in ((0, -0.1), (1, 0.1)):
                con.execute("INSERT INTO rte_frames VALUES ('fixed', 'ndt', ?, ?, ?, ?)",
                            [seq, trial, frame, y + dy + (trial - 2)])
    con.close()


def test_novelty_fallback_is_fixed_only_where_it_beats_the_defaults_everywhere(
    tmp_path: Path,
) -> None:
    space = get_adapter("ndt").space.to_json()
    fallback_db(tmp_path / "a.duckdb", {"cave_0": 1.0, "street_0": 0.6},
                {"cave_0": 3.0, "street_0": 0.7})
    defaults = get_adapter("ndt").space.defaults()
    evidence = read_fallback_evidence(tmp_path / "a.duckdb", "ndt", defaults)
    assert evidence is not None and evidence.fixed_trial == 2
    assert evidence.fixed == {"resolution": 2.5, "keyframe_interval": 6.0}
    assert sorted(evidence.per_sequence) == ["cave_0", "street_0"]
    np.testing.assert_allclose(evidence.per_sequence["cave_0"], (1.0, 3.0))
    np.testing.assert_allclose(evidence.per_sequence["street_0"], (0.6, 0.7))
    params, record = novelty_fallback(tmp_path / "a.duckdb", "ndt", space, "auto")
    assert params == evidence.fixed and record["chosen"] == "fixed"
    # the defaults win one sequence: auto keeps them, 'fixed' does not ask
    fallback_db(tmp_path / "b.duckdb", {"cave_0": 1.0, "street_0": 0.8},
                {"cave_0": 3.0, "street_0": 0.7})
    params, record = novelty_fallback(tmp_path / "b.duckdb", "ndt", space, "auto")
    assert params is None and record["chosen"] == "defaults"
    assert record["per_sequence"]["street_0"] == pytest.approx(
        {"fixed_rte_pct": 0.8, "defaults_rte_pct": 0.7})
    assert novelty_fallback(tmp_path / "b.duckdb", "ndt", space, "fixed")[0] == evidence.fixed
    assert novelty_fallback(tmp_path / "b.duckdb", "ndt", space, "defaults")[0] is None
    # per_scan: the runtime weighs both, so the artifact carries the fixed parameters
    params, record = novelty_fallback(tmp_path / "b.duckdb", "ndt", space, "per_scan")
    assert params == evidence.fixed and record["chosen"] == "per_scan"
    with pytest.raises(ConfigError, match="novelty_fallback must be one of"):
        choose_fallback("fixed-ish", evidence)
    for mode in ("fixed", "per_scan"):
        with pytest.raises(InputError, match="needs the joint study"):
            choose_fallback(mode, None)


def test_the_forest_runtime_predicts_like_scikit_learn(kitti_root: Path) -> None:
    """The exported forest walked with numpy gives scikit-learn's predictions."""
    from pipeline.surrogates.base import TrainingSet
    from pipeline.surrogates.forest import ForestSurrogate

    rows, _ = synthetic_rows(kitti_root, trials=12)
    settings = SurrogateSection(model="forest", forest={"trees": 6, "max_samples": 300})
    training = TrainingSet(rows.E, np.arange(len(rows.y) + 1), rows.U, np.log1p(rows.y))
    estimator = ForestSurrogate._estimator(settings, len(rows.y))
    estimator.fit(training.features(), training.rows_t)
    exported = ForestSurrogate.export(estimator, settings)
    E = rows.E[::7] + 0.05
    queries = np.hstack([E, np.random.default_rng(2).random((len(E), 2))])
    np.testing.assert_allclose(exported.predict(queries), estimator.predict(queries), rtol=1e-12)
    assert len(exported.roots) == 6 and exported.to_json()["nodes"] == len(exported.feature)


@pytest.mark.parametrize("grouped", [True, False])
def test_the_cross_validation_knn_equals_a_flat_knn(grouped: bool) -> None:
    """GroupedKnnRegressor (the selector's exact grouped search, used by the
    leave-one-sequence-out CV) predicts the kNN mean of scikit-learn's flat search, on rows
    that group by trial set and (fallback) on rows that do not."""
    from sklearn.neighbors import KNeighborsRegressor

    from pipeline.surrogates.knn import GroupedKnnRegressor

    rng = np.random.default_rng(3)
    blocks = []
    for _ in range(3 if grouped else 70):  # sequences (groups), each its own trials
        trials = rng.uniform(0, 3, (6, 2))
        for _ in range(9 if grouped else 1):  # frames
            e = rng.normal(size=4)
            blocks.append(np.hstack([np.repeat(e[None], len(trials), 0), trials]))
    rows = np.vstack(blocks)
    t = rng.lognormal(size=len(rows))
    queries = np.hstack([np.repeat(rng.normal(size=(5, 4)), 7, 0), rng.uniform(0, 3, (35, 2))])
    ours = GroupedKnnRegressor(5, 2).fit(rows, t)
    assert (ours.groups is not None) == grouped
    np.testing.assert_allclose(ours.predict(queries),
                               KNeighborsRegressor(n_neighbors=5).fit(rows, t).predict(queries),
                               rtol=1e-12)
