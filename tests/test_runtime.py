"""The deployable runtime: light imports, artifact verification, selection, schedules, CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.models import SEL, build_model, kitti_scan, write_tiny_sequence
from sklearn.neighbors import KNeighborsRegressor

from pipeline.artifact import canonical_manifest_hash
from pipeline.errors import ArtifactError
from pipeline.odometry.base import Schedule
from pipeline.odometry.registry import get_adapter
from pipeline.runtime import TIE_TOL, Selector, load_model
from pipeline.sequence import SequenceReader
from pipeline.surrogates import knn_search
from pipeline.surrogates.base import environment_d2
from pipeline.surrogates.knn_search import GroupedNeighbourhood, Neighbourhood, knn_mean_numpy
from pipeline.surrogates.section import SurrogateSection
from stages.cli import main

REPO = Path(__file__).resolve().parents[1]
HEAVY = (
    "sklearn",
    "duckdb",
    "hyperopt",
    "open3d",
    "dvc",
    "pyarrow",
    "click",
    "small_gicp",
    "kiss_icp",
    "dask",
    "matplotlib",
    "pydantic",
)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Path:
    return build_model(tmp_path_factory.mktemp("m") / "model", kitti_root)


def test_import_is_light() -> None:
    out = subprocess.run(
        [sys.executable, "-c", "import pipeline.runtime, sys; print(sorted(sys.modules))"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    loaded = {m.split(".")[0] for m in eval(out)}
    assert not loaded & set(HEAVY), loaded & set(HEAVY)
    assert "numpy" in loaded and "scipy" not in loaded  # the kd-trees load on first use


def copy_model(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for p in src.iterdir():
        (dst / p.name).write_bytes(p.read_bytes())
    return dst


def test_every_flipped_byte_is_refused(model_dir: Path, tmp_path: Path) -> None:
    names = sorted(p.name for p in model_dir.iterdir())
    assert "manifest.json" in names and len(names) == 10
    for name in names:
        size = (model_dir / name).stat().st_size
        positions = (
            [0, size // 2, size - 2]
            if name != "manifest.json"
            else list(range(0, size, max(1, size // 40)))
        )
        for pos in positions:
            bad = copy_model(model_dir, tmp_path / f"{name}.{pos}")
            data = bytearray((bad / name).read_bytes())
            data[pos] ^= 0x01
            if name == "manifest.json" and _same_json(bytes(data), model_dir / name):
                continue  # the 17th digit of a float: the same number, the same manifest
            (bad / name).write_bytes(bytes(data))
            with pytest.raises(ArtifactError) as exc:
                load_model(bad)
            msg = str(exc.value)
            assert "\n" not in msg and str(bad) in msg, msg


def _same_json(data: bytes, original: Path) -> bool:
    """Whether ``data`` is JSON that says what ``original`` says (a flipped last digit of a
    17-digit float can give the same double)."""
    try:
        return bool(json.loads(data) == json.loads(original.read_bytes()))
    except (ValueError, UnicodeDecodeError):
        return False


def rewrite_manifest(dst: Path, **changes: object) -> None:
    manifest = json.loads((dst / "manifest.json").read_text())
    manifest.update(changes)
    manifest["manifest_sha256"] = canonical_manifest_hash(manifest)
    (dst / "manifest.json").write_text(json.dumps(manifest))


def test_wrong_schema_version_and_algorithm(model_dir: Path, tmp_path: Path) -> None:
    bad = copy_model(model_dir, tmp_path / "v2")
    rewrite_manifest(bad, schema_version="3.0")
    with pytest.raises(ArtifactError, match=r"schema version '3\.0'"):
        load_model(bad)
    with pytest.raises(ArtifactError, match="algorithm 'ndt', expected 'gicp'"):
        load_model(model_dir, expected_algorithm="gicp")
    gone = copy_model(model_dir, tmp_path / "gone")
    (gone / "rows_t.npy").unlink()
    with pytest.raises(ArtifactError, match=r"rows_t\.npy: no such model file \(listed in"):
        load_model(gone)


def test_cli_refuses_bad_artifacts(model_dir: Path, tmp_path: Path, kitti_root: Path) -> None:
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "04", n=3)
    flipped = copy_model(model_dir, tmp_path / "flipped")
    data = bytearray((flipped / "env.npy").read_bytes())
    data[-3] ^= 0x10
    (flipped / "env.npy").write_bytes(bytes(data))
    v2 = copy_model(model_dir, tmp_path / "v2")
    rewrite_manifest(v2, schema_version="3.0")
    cases = [
        *[(["select", str(model_dir), str(seq), "--period-s", v],
           f"select.period_s must be a finite number > 0, got {v}") for v in ("0", "-1", "nan")],
        (["select", str(flipped), str(seq)], "sha256 mismatch"),
        (["select", str(v2), str(seq)], "schema version"),
        (["select", str(model_dir), str(seq), "--algorithm", "gicp"], "expected 'gicp'"),
        (["live", str(model_dir), str(seq), "--algorithm", "kiss_icp"], "expected 'kiss_icp'"),
    ]
    for i, (args, message) in enumerate(cases):
        out = tmp_path / f"out{i}.{'mcap' if args[0] == 'live' else 'parquet'}"
        res = CliRunner().invoke(main, [*args, "--out", str(out)])
        assert res.exit_code == 1, res.output
        assert res.output.startswith("adaptune: error: ") and message in res.output
        assert res.output.count("\n") == 1 and "Traceback" not in res.output
        assert not out.exists()


def test_schedule_in_range_for_every_scan(
    model_dir: Path, tmp_path: Path, kitti_root: Path
) -> None:
    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "06", n=8, step=2)
    model = load_model(model_dir, "ndt")
    space = get_adapter("ndt").space
    with SequenceReader(seq) as reader:
        sched = Selector(model, SEL.replace(period_s=0.3)).schedule(reader)
    sched.validate(space, 8)  # every frame covered, every value in range
    # selections at frames 0, 3, 6 (0.3 s at 10 Hz), held in between
    for a, b in ((0, 1), (1, 2), (3, 4), (4, 5), (6, 7)):
        assert sched.at(a) == sched.at(b)
    out = tmp_path / "sched.parquet"
    res = CliRunner().invoke(main, ["select", str(model_dir), str(seq), "--out", str(out)])
    assert res.exit_code == 0, res.output
    read = Schedule.read(out)
    read.validate(space, 8)
    assert len(read.changes()) == 1  # period 1 s (select's default): one selection in 0.8 s
    csv = tmp_path / "sched.csv"  # the same rows as CSV, for a node without pyarrow
    res = CliRunner().invoke(main, ["select", str(model_dir), str(seq), "--out", str(csv)])
    assert res.exit_code == 0, res.output
    rows = csv.read_text().splitlines()
    assert rows[0] == "frame,stamp_ns," + ",".join(read.values)
    assert [float(v) for v in rows[1].split(",")[2:]] == list(read.at(0).values())
    assert [int(r.split(",")[1]) for r in rows[1:]] == read.stamps_ns.tolist()


def test_too_few_points_keep_last(model_dir: Path, kitti_root: Path) -> None:
    model = load_model(model_dir)
    sel = Selector(model, SEL)
    assert sel.select(np.zeros((10, 4), np.float32)) == model.defaults()  # before any selection
    first = sel.select(kitti_scan(kitti_root, "01", 0))
    assert sel.select(kitti_scan(kitti_root, "04", 0)[:999]) == sel.current
    assert sel.last["kept"] == "too_few_points"
    assert sel.current_u is not None and model.params_of(sel.current_u) == sel.current
    assert set(first) == {"resolution", "keyframe_interval"}


def full_knn(model, e_s: np.ndarray, U: np.ndarray, risk: float = 0.0) -> np.ndarray:
    """scikit-learn's kNN over ALL rows of the artifact, at (e_s, U): the mean of the k
    neighbours' targets, plus risk times their (population) std."""
    knn_model = model.surrogate
    counts = np.diff(knn_model.env_offsets)
    feats = np.hstack([np.repeat(model.env, counts, axis=0), knn_model.rows_x])
    knn = KNeighborsRegressor(n_neighbors=knn_model.k).fit(feats, knn_model.rows_t)
    q = np.hstack([np.repeat(e_s[None], len(U), 0), U * model.x_scale])
    if risk == 0.0:
        return knn.predict(q)
    t = knn_model.rows_t[knn.kneighbors(q, return_distance=False)]
    return t.mean(axis=1) + risk * t.std(axis=1)


RISKS = pytest.mark.parametrize("risk", [0.0, 0.5])


@RISKS
def test_grouped_search_is_the_exact_knn_over_every_row(
    model_dir: Path, kitti_root: Path, risk: float
) -> None:
    model = load_model(model_dir)
    sel = Selector(model, SEL.replace(hysteresis=0.0, refine_iters=0, risk=risk))
    groups = sel.search.groups
    assert groups is not None and len(groups.trees) == 4  # one group per sequence
    off = np.random.default_rng(3).random((50, 2))  # points off the candidate set too
    for seq, frame in (("01", 5), ("10", 2), ("06", 9)):
        e_s = model.environment(kitti_scan(kitti_root, seq, frame))
        nb = sel.neighbourhood(e_s)
        assert isinstance(nb, GroupedNeighbourhood)
        brute = full_knn(model, e_s, sel.candidates, risk)
        values = nb.candidate_values(sel.candidates)
        np.testing.assert_allclose(values, brute, rtol=1e-12)
        np.testing.assert_allclose(nb.predict(off).t, full_knn(model, e_s, off, risk),
                                   rtol=1e-12)
        numpy_path = knn_mean_numpy(
            *groups.candidate_trials, nb.frame_d2, nb.frame_row0, model.surrogate.rows_t,
            model.surrogate.k, risk,
        )
        np.testing.assert_allclose(numpy_path, values, rtol=1e-12)  # the no-numba fallback
        tree = Neighbourhood(model.surrogate, environment_d2(model.env, e_s),
                             len(model.surrogate.rows_t), model.x_scale, risk)
        np.testing.assert_array_equal(tree.predict(sel.candidates).t, values)  # same bits
        chosen = sel.select_environment(e_s)  # one of the candidates of least value (ties)
        least = sel.candidates[brute <= brute.min() + TIE_TOL]
        assert chosen in [model.params_of(u) for u in least]


def test_frames_with_their_own_row_order_form_their_own_group(
    model_dir: Path, kitti_root: Path
) -> None:
    model = load_model(model_dir)
    knn = model.surrogate
    a, b = knn.env_offsets[0], knn.env_offsets[1]
    perm = np.arange(len(knn.rows_t))
    perm[a:b] = perm[a:b][::-1]  # frame 0 lists its trials backwards
    shuffled = replace(model, surrogate=replace(knn, rows_x=knn.rows_x[perm],
                                                rows_t=knn.rows_t[perm]))
    sel = Selector(shuffled, SEL.replace(hysteresis=0.0, refine_iters=0))
    assert sel.search.groups is not None and len(sel.search.groups.trees) == 5
    e_s = model.environment(kitti_scan(kitti_root, "01", 0))
    np.testing.assert_allclose(
        sel.neighbourhood(e_s).candidate_values(sel.candidates),
        full_knn(model, e_s, sel.candidates),
        rtol=1e-12,
    )


@RISKS
def test_ungrouped_artifacts_use_the_certified_tree(
    model_dir: Path, kitti_root: Path, monkeypatch: pytest.MonkeyPatch, risk: float
) -> None:
    model = load_model(model_dir)
    monkeypatch.setattr(knn_search, "MAX_GROUPS", 3)  # the 4 sequences no longer qualify
    assert Selector(model, SEL).search.groups is None
    for seq, frame in (("01", 5), ("10", 2), ("06", 9)):
        e_s = model.environment(kitti_scan(kitti_root, seq, frame))
        sel = Selector(model, SEL.replace(hysteresis=0.0, refine_iters=0, subset_rows=200,
                                          risk=risk))
        nb = sel.neighbourhood(e_s)
        assert isinstance(nb, Neighbourhood)
        pred = nb.predict(sel.candidates)
        brute = full_knn(model, e_s, sel.candidates, risk)
        assert pred.exact.any()
        np.testing.assert_allclose(pred.t[pred.exact], brute[pred.exact], rtol=1e-12)
        # the bounded query of the search: the same certified values, inf elsewhere
        cert = nb.certified(sel.candidates)
        assert (np.isfinite(cert) == pred.exact).all()
        np.testing.assert_allclose(cert[pred.exact], brute[pred.exact], rtol=1e-12)
        # with every row in the subset every candidate is certified and exact
        d2 = ((model.env - e_s) ** 2).sum(1)
        everything = Neighbourhood(model.surrogate, d2, len(model.surrogate.rows_t),
                                   model.x_scale, risk)
        allp = everything.predict(sel.candidates)
        assert allp.exact.all()
        np.testing.assert_allclose(allp.t, brute, rtol=1e-12)
        chosen = sel.select_environment(e_s)
        certified = np.where(pred.exact, brute, np.inf)
        best = sel.candidates[certified <= certified.min() + TIE_TOL]  # ties: any of them
        assert chosen in [model.params_of(u) for u in best]


def test_refinement_and_hysteresis(model_dir: Path, kitti_root: Path) -> None:
    model = load_model(model_dir)
    e_s = model.environment(kitti_scan(kitti_root, "01", 1))
    plain = Selector(model, SEL.replace(refine_iters=0))
    refined = Selector(model, SEL.replace(refine_iters=6))
    plain.select_environment(e_s)
    refined.select_environment(e_s)
    assert refined.last["predicted_t"] <= plain.last["predicted_t"]
    sticky = Selector(model, SEL.replace(hysteresis=1e9))
    p0 = sticky.select_environment(model.environment(kitti_scan(kitti_root, "01", 0)))
    assert sticky.select_environment(model.environment(kitti_scan(kitti_root, "10", 9))) == p0
    assert sticky.last["kept"] == "hysteresis"


@pytest.mark.parametrize("window", [1, 5])
@RISKS
def test_shared_nearest_trials_give_the_same_schedule(
    model_dir: Path, tmp_path: Path, kitti_root: Path, window: int, risk: float
) -> None:
    """The nearest trials of the pattern search's probes are found once for the whole window
    (``TrialGroups.reuse``), not once per scan of it, and the probes of a start that did not
    move are not asked again in the next round (``Selector.reuse``): the schedule is the one
    of the search that does neither, bit for bit (the default refinement, no hysteresis), with
    fewer points asked."""
    from pipeline.selection import SelectionSettings

    class Counting(Selector):
        """A Selector counting the points its pattern search asks the window for."""

        asked = 0

        def _certified(self, U: np.ndarray) -> np.ndarray:
            self.asked += len(U)
            return super()._certified(U)

    seq = tmp_path / "s.mcap"
    write_tiny_sequence(seq, kitti_root, "10", n=10, step=2)
    model = load_model(model_dir)
    schedules, asked = [], []
    for reuse in (False, True):
        sel = Counting(model, SelectionSettings(period_s=0.05, hysteresis=0.0, window=window,
                                                risk=risk))
        sel.novelty_distance = float("inf")  # every scan searched
        assert sel.search.groups is not None
        sel.search.groups.reuse = sel.reuse = reuse
        with SequenceReader(seq) as reader:
            schedules.append(sel.schedule(reader))
        asked.append(sel.asked)
    old, new = schedules
    assert old.values.keys() == new.values.keys()
    for name in old.values:
        assert old.values[name].tobytes() == new.values[name].tobytes(), name
    assert len(old.changes()) > 1  # the schedule does select (not the defaults throughout)
    assert asked[1] < asked[0]


def test_first_of_the_order_are_those_of_the_whole_order(model_dir: Path) -> None:
    """``Selector._order(t, U, first=n)`` sorts only the lowest ranks: the same n indices as
    the whole order, ties (values within TIE_TOL, equal distances) included."""
    model = load_model(model_dir)
    sel = Selector(model, SEL)
    rng = np.random.default_rng(3)
    U = sel.candidates
    for trial in range(20):
        t = np.round(rng.random(len(U)), 2)  # many exact ties
        t[rng.random(len(U)) < 0.3] = np.inf  # uncertified values
        sel.current_u = None if trial % 2 else U[trial]
        for n in (1, 3, 7):
            assert np.array_equal(sel._order(t, U, first=n), sel._order(t, U)[:n])
    assert np.array_equal(sel._order(np.full(len(U), np.inf), U, first=3),
                          sel._order(np.full(len(U), np.inf), U)[:3])


def test_unfamiliar_scans_get_the_fallback(tmp_path: Path, kitti_root: Path) -> None:
    """Novelty guard: an environment farther than novelty_distance from every training frame
    gets the fallback (the defaults unless the manifest names parameters); a familiar one gets
    the surrogate's choice again."""
    model = load_model(build_model(tmp_path / "model", kitti_root))
    limit = model.novelty_distance
    assert limit > 0
    sel = Selector(model, SEL.replace(hysteresis=0.0))
    familiar = model.env[3]
    far = familiar + 3.0 * limit / np.sqrt(len(familiar))  # 3 limits from that frame
    assert np.sqrt(((model.env - far) ** 2).sum(1)).min() > limit
    first = sel.select_environment(familiar)
    assert sel.last["kept"] == "" and sel.last["nearest_environment"] == 0.0
    assert sel.select_environment(far) == model.defaults()
    assert sel.last["kept"] == "novel" and sel.current == model.defaults()
    assert sel.select_environment(familiar) == first
    assert first != model.defaults()
    # a manifest with fallback parameters (the joint study's, chosen by the surrogate stage)
    chosen = {"resolution": 2.5, "keyframe_interval": 6.0}
    fixed_record = {"mode": "fixed", "chosen": "fixed"}
    fixed = Selector(load_model(build_model(tmp_path / "fixed", kitti_root, fallback=fixed_record,
                                            fallback_params=chosen)), SEL)
    assert fixed.select_environment(far) == chosen and fixed.last["kept"] == "novel"
    assert fixed.select_environment(familiar) == first
    # fallback values that do not survive the unit-cube round trip bit for bit (the base NDT
    # artifact's fixed parameters): what a novel scan returns is what is then held
    odd = {"resolution": 2.1933988413775443, "keyframe_interval": 7.774158360578929}
    held = Selector(load_model(build_model(tmp_path / "odd", kitti_root, fallback=fixed_record,
                                           fallback_params=odd)), SEL)
    assert held.model.params_of(held.anchor_u) != odd  # the case at hand
    got = held.select_environment(far)
    assert got == held.current and got == pytest.approx(odd, rel=1e-15)
    assert held.select_environment(far) == got
    # without a novelty distance (null in the manifest) the surrogate always decides
    off = load_model(build_model(tmp_path / "off", kitti_root,
                                 settings=SurrogateSection(n_sobol=256, cv_max_frames=5,
                                                            novelty_quantile=None)))
    assert off.novelty_distance is None
    unguarded = Selector(off, SEL.replace(hysteresis=0.0))
    unguarded.select_environment(far)
    assert unguarded.last["kept"] != "novel"
