"""The selector's robustness (issue 12): no chaos from rounding or candidate order, the
environment window, the anchor. Small synthetic artifact of tests/test_surrogate.py."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers.models import DEFAULTS_FALLBACK, SEL, build_model, kitti_scan

from pipeline.descriptors import NdtHistogram
from pipeline.odometry.registry import get_adapter
from pipeline.pca import Pca
from pipeline.runtime import Model, Selector, load_model
from pipeline.selection import SelectionSettings
from pipeline.surrogates.fit import fit_surrogate
from pipeline.surrogates.knn_search import canonical_mean, canonical_value, knn_mean_numpy
from pipeline.surrogates.rows import TrainingRows
from pipeline.surrogates.section import SurrogateSection
from pipeline.surrogates.writer import ArtifactInfo, write_artifact


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory, kitti_root: Path) -> Model:
    return load_model(build_model(tmp_path_factory.mktemp("m") / "model", kitti_root))


def drive(model: Model, kitti_root: Path) -> list[np.ndarray]:
    """A run of environments: KITTI scans, training frames and points between them."""
    scans = [model.environment(kitti_scan(kitti_root, s, f))
             for s, f in (("01", 3), ("04", 7), ("06", 1), ("10", 8), ("01", 9))]
    between = [0.5 * (model.env[i] + model.env[j]) for i, j in ((0, 15), (7, 30), (22, 39))]
    return [*scans, *between, *model.env[::5]]


def schedule(sel: Selector, envs: list[np.ndarray]) -> list[dict[str, float]]:
    return [sel.select_environment(e) for e in envs]


def with_candidates(sel: Selector, order: np.ndarray) -> Selector:
    """The same selector with its candidate set in another order."""
    sel.candidates = sel.candidates[order]
    sel.search = sel.model.surrogate.search(sel.candidates, sel.model.x_scale,
                                            {"subset_rows": sel.settings.subset_rows,
                                             "grouped": True})
    return sel


def test_the_candidates_order_does_not_choose(model: Model, kitti_root: Path) -> None:
    """Many candidates share their predicted value exactly (the same k neighbours); which one
    is chosen must not depend on where it stands in the candidate set."""
    envs = drive(model, kitti_root)
    ref = schedule(Selector(model, SEL.replace(refine_iters=2)), envs)
    sel = Selector(model, SEL)
    ties = [(v == v.min()).sum() for v in
            (sel.neighbourhood(e).candidate_values(sel.candidates) for e in envs)]
    assert max(ties) > 1, ties  # exact ties at the minimum: the case at hand
    for seed in range(3):
        order = np.random.default_rng(seed).permutation(len(sel.candidates))
        shuffled = with_candidates(Selector(model, SEL.replace(refine_iters=2)), order)
        assert schedule(shuffled, envs) == ref


def test_last_bit_changes_do_not_choose(model: Model, kitti_root: Path) -> None:
    """A 1e-12 relative change of E (another BLAS's PCA, another machine's descriptor) leaves
    every selection as it was."""
    envs = drive(model, kitti_root)
    ref = schedule(Selector(model, SEL.replace(refine_iters=2, window=2)), envs)
    rng = np.random.default_rng(0)
    for _ in range(3):
        nudged = [e * (1 + 1e-12 * rng.standard_normal(e.shape)) for e in envs]
        assert schedule(Selector(model, SEL.replace(refine_iters=2, window=2)), nudged) == ref


@pytest.mark.parametrize("risk", [0.0, 0.5])
def test_the_same_neighbours_give_the_same_bits(model: Model, kitti_root: Path,
                                                risk: float) -> None:
    """The kNN mean (+ risk * std) does not depend on the order the neighbours were found in,
    and the numba and numpy searches agree to the last bit."""
    t = np.random.default_rng(0).lognormal(size=(200, 7))
    shuffled = np.random.default_rng(1).permuted(t, axis=1)
    np.testing.assert_array_equal(canonical_value(shuffled, risk), canonical_value(t, risk))
    np.testing.assert_allclose(canonical_value(t, risk), t.mean(1) + risk * t.std(1),
                               rtol=1e-13)
    assert (shuffled.mean(axis=1) != t.mean(axis=1)).any()  # what a plain mean does
    sel = Selector(model, SEL.replace(risk=risk))
    groups = sel.search.groups
    assert groups is not None
    for e_s in drive(model, kitti_root)[:4]:
        nb = sel.neighbourhood(e_s)
        np.testing.assert_array_equal(
            knn_mean_numpy(*groups.candidate_trials, nb.frame_d2, nb.frame_row0,
                           model.surrogate.rows_t, model.surrogate.k, risk),
            nb.candidate_values(sel.candidates))


def test_risk_zero_is_the_plain_mean_to_the_last_bit(model: Model, kitti_root: Path) -> None:
    """risk = 0 (the default) gives the kNN mean of before, bit for bit, and the same
    schedule."""
    envs = drive(model, kitti_root)
    plain = Selector(model, SEL.replace(refine_iters=2))
    zero = Selector(model, SEL.replace(refine_iters=2, risk=0.0))
    assert zero.settings.risk == plain.settings.risk == 0.0
    assert schedule(zero, envs) == schedule(plain, envs)
    U = zero.candidates[:40]
    for e_s in envs[:3]:
        rows = np.stack([knn_rows(model, e_s, u) for u in U])
        np.testing.assert_array_equal(zero.neighbourhood(e_s).predict(U).t,
                                      canonical_mean(model.surrogate.rows_t[rows]))


def knn_rows(model: Model, e_s: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The rows of the k nearest training rows of (e_s, u) by brute force: (k,)."""
    knn = model.surrogate
    counts = np.diff(knn.env_offsets)
    d2 = (np.repeat(((model.env - e_s) ** 2).sum(1), counts)
          + ((knn.rows_x - u * model.x_scale) ** 2).sum(1))
    return np.argsort(d2, kind="stable")[: knn.k]


def four_frame_rows(u_a: tuple[float, ...] | np.ndarray, u_b: tuple[float, ...] | np.ndarray,
                    rte: Callable[[int, float], tuple[float, float]]) -> TrainingRows:
    """Training rows of two trials, A and B at unit points ``u_a``, ``u_b``, on four frames:
    sequences s0, s1 x frames at E = -1, +1; ``rte(i, e)`` -> (A's, B's RTE [%]) on frame E = e
    of sequence s<i>."""
    E, U, y, seqs, idx, trials = [], [], [], [], [], []
    for i, seq in enumerate(("s0", "s1")):
        for frame, e in enumerate((-1.0, 1.0)):
            for trial, (u, y_u) in enumerate(zip((u_a, u_b), rte(i, e), strict=True)):
                E.append([e])
                U.append(u)
                y.append(y_u)
                seqs.append(seq)
                idx.append(frame)
                trials.append(trial)
    return TrainingRows(np.array(E), np.array(U), np.array(y), np.array(seqs), np.array(idx),
                        np.array(trials))


def write_small(out: Path, fitted: Any, space: list[dict[str, Any]],
                fallback: dict[str, Any] | None = None,
                fallback_params: dict[str, float] | None = None) -> None:
    """The artifact of a one-dimensional environment (a PCA that keeps the first bin)."""
    pca = Pca(np.zeros(90), np.ones(90), np.eye(1, 90), np.ones(1))
    write_artifact(out, fitted, pca, ArtifactInfo("ndt", space, NdtHistogram(),
                                                  fallback or DEFAULTS_FALLBACK, fallback_params))


def spread_model(out: Path) -> Path:
    """An artifact of two trials, A = (0.1, 0.5) and B = (0.9, 0.5) in the cube, run on four
    frames (two sequences x two frames, E = -1 or +1): A scores 0.2 % or 2.4 % RTE by frame
    (log1p: mean 0.703, std 0.521), B 1.2 % everywhere (0.788, std 0). With k = 4 the
    neighbours of A are the four A rows (B's rows are 2.77 away in X_s, the frames at most 2
    in E_s), of B the four B rows."""
    rows = four_frame_rows((0.1, 0.5), (0.9, 0.5),
                           lambda i, e: (0.2 if (i == 0) == (e < 0) else 2.4, 1.2))
    section = SurrogateSection(k=4, n_sobol=0, cv_max_frames=2, novelty_quantile=None)
    space = get_adapter("ndt").space.to_json()
    write_small(out, fit_surrogate(rows, space, section), space)
    return out


@pytest.mark.parametrize("grouped", [True, False])
def test_risk_prefers_the_parameters_whose_neighbours_agree(tmp_path: Path,
                                                           grouped: bool) -> None:
    """risk = 0 (the default) picks A (the lower mean), risk = 1 picks B (A's neighbours
    disagree), by either search."""
    model = load_model(spread_model(tmp_path / "spread"))
    a, b = (model.params_of(np.array(u)) for u in ((0.1, 0.5), (0.9, 0.5)))
    t_a, t_b = np.log1p([0.2, 2.4, 2.4, 0.2]), np.log1p([1.2] * 4)
    e_s = model.env[0]
    for risk, want, t in ((0.0, a, t_a.mean()), (1.0, b, t_b.mean()),
                          (0.1, a, t_a.mean() + 0.1 * t_a.std())):
        sel = Selector(model, SelectionSettings(risk=risk), grouped=grouped)
        assert sel.select_environment(e_s) == want
        assert sel.last["predicted_t"] == pytest.approx(t, rel=1e-12)
    assert Selector(model, grouped=grouped).select_environment(e_s) == a
    # the hysteresis weighs risk-adjusted values: from A (1.224), B (0.788) is 0.436 better
    for hysteresis, want, kept in ((0.4, b, ""), (0.5, a, "hysteresis")):
        sel = Selector(model, SelectionSettings(risk=1.0, hysteresis=hysteresis),
                       grouped=grouped)
        sel.current_u = next(u for u in sel.candidates if model.params_of(u) == a)
        assert sel.select_environment(model.env[0]) == want
        assert sel.last["kept"] == kept


@pytest.mark.parametrize("risk", [0.0, 0.5])
def test_the_window_minimises_the_mean_over_recent_environments(model: Model, kitti_root: Path,
                                                                  risk: float) -> None:
    """The window averages S, risk-adjusted when risk > 0, over the last W scans."""
    a, b, c = drive(model, kitti_root)[:3]
    sel = Selector(model, SEL.replace(window=2, refine_iters=0, risk=risk))
    sel.select_environment(a)
    sel.select_environment(b)
    chosen = sel.select_environment(c)
    mean = (sel.neighbourhood(b).candidate_values(sel.candidates)
            + sel.neighbourhood(c).candidate_values(sel.candidates)) / 2  # a left the window
    assert sel.last["predicted_t"] == pytest.approx(mean.min(), abs=1e-9)
    assert mean[[model.params_of(u) == chosen for u in sel.candidates]].min() == pytest.approx(
        mean.min(), abs=1e-9)
    one = Selector(model, SEL.replace(window=1, refine_iters=0, risk=risk))
    for e in (a, b, c):
        one.select_environment(e)
    assert one.last["predicted_t"] == pytest.approx(
        one.neighbourhood(c).candidate_values(one.candidates).min(), abs=1e-9)


def test_the_anchor_is_left_only_for_a_predicted_gain(model: Model, kitti_root: Path) -> None:
    e_s = drive(model, kitti_root)[0]
    free = Selector(model, SEL.replace(anchor_margin=0.0))
    assert free.select_environment(e_s) != model.fallback()
    assert free.last["kept"] == ""
    anchored = Selector(model, SEL.replace(anchor_margin=1e9))
    assert anchored.select_environment(e_s) == model.fallback()
    assert anchored.last["kept"] == "anchor"


def test_the_trust_region_keeps_every_choice_near_the_fallback(model: Model,
                                                               kitti_root: Path) -> None:
    """With ``trust_radius`` r every selection lies within r of the fallback parameters in
    every unit-cube coordinate; without it the same scans go farther."""
    envs = drive(model, kitti_root)
    anchor = model.to_unit(np.array([[model.fallback()[n] for n in model.names]]))[0]

    def farthest(sel: Selector) -> float:
        chosen = [sel.select_environment(e) for e in envs]
        units = model.to_unit(np.array([[c[n] for n in model.names] for c in chosen]))
        return float(np.abs(units - anchor).max())

    assert farthest(Selector(model, SEL)) > 0.2
    assert farthest(Selector(model, SEL.replace(trust_radius=0.2))) <= 0.2 + 1e-9
    tight = Selector(model, SEL.replace(trust_radius=1e-6))
    assert all(tight.select_environment(e) == tight.model.params_of(tight.anchor_u)
               for e in envs)


ONE_SCAN = SelectionSettings(window=1)
"""The default selector on the newest scan only (the per-scan fallback's tests)."""


def two_sets_model(out: Path, per_scan: bool) -> tuple[Path, dict[str, float], dict[str, float]]:
    """An artifact of two trials, the NDT defaults D and a 'fixed' set F, run on four frames
    (two sequences x two frames, E = -1 or +1): D scores 0.3 % at E = -1 and 3 % at E = +1, F
    the reverse. Novelty distance 2 (in E units): scans at E = -5 and +5 are unfamiliar, and
    their k = 2 nearest rows are those of the frames at E = -1 and +1 respectively. The
    fallback is ``per_scan`` (D or F by S at the scan) or the defaults for every such scan.
    Returns (artifact, D, F)."""
    space_obj = get_adapter("ndt").space
    space = space_obj.to_json()
    cube_d = space_obj.to_unit(space_obj.defaults())
    cube_f = np.array([0.9, 0.9])
    rows = four_frame_rows(cube_d, cube_f, lambda i, e: (0.3, 3.0) if e < 0 else (3.0, 0.3))
    section = SurrogateSection(k=2, n_sobol=0, cv_max_frames=2, novelty_quantile=None)
    fitted = fit_surrogate(rows, space, section)
    fitted.novelty_distance = 2.0 * float(np.abs(fitted.env).max())  # E = +-1 is env +-max
    d, f = space_obj.from_unit(cube_d[None]), space_obj.from_unit(cube_f[None])
    record = ({"mode": "per_scan", "chosen": "per_scan"} if per_scan
              else {"mode": "defaults", "chosen": "defaults"})
    write_small(out, fitted, space, record, f if per_scan else None)
    return out, d, f


def test_a_per_scan_fallback_weighs_the_defaults_against_the_fixed_parameters(
        tmp_path: Path) -> None:
    """Unfamiliar scans get the defaults or the fixed parameters, whichever the surrogate
    predicts better at the scan, with the hysteresis; the single fallback gives one set to
    every unfamiliar scan."""
    path, d, f = two_sets_model(tmp_path / "per_scan", per_scan=True)
    model = load_model(path)
    assert model.per_scan_fallback and model.fallback() == pytest.approx(f)
    scale = float(np.abs(model.env).max())
    near_d, near_f, familiar = (np.array([v * scale]) for v in (-5.0, 5.0, -1.0))
    sel = Selector(model, ONE_SCAN)
    assert sel.select_environment(near_d) == pytest.approx(d)
    assert sel.last["kept"] == "novel"
    assert sel.select_environment(near_f) == pytest.approx(f)  # better by 1.12 > 0.02
    assert sel.select_environment(familiar) == pytest.approx(d)  # the surrogate's own choice
    assert sel.last["kept"] == ""
    # a hysteresis larger than the predicted gain keeps the fallback in force
    held = Selector(model, ONE_SCAN.replace(hysteresis=5.0))
    assert held.select_environment(near_f) == pytest.approx(f)
    assert held.select_environment(near_d) == pytest.approx(f)
    # the window averages the unfamiliar scans' S: one scan each way ties, and ties hold
    windowed = Selector(model, ONE_SCAN.replace(window=2, hysteresis=0.0))
    assert windowed.select_environment(near_d) == pytest.approx(d)
    assert windowed.select_environment(near_f) == pytest.approx(d)
    assert windowed.select_environment(near_f) == pytest.approx(f)
    single = load_model(two_sets_model(tmp_path / "single", per_scan=False)[0])
    assert not single.per_scan_fallback
    one = Selector(single, ONE_SCAN)
    assert [one.select_environment(e) for e in (near_d, near_f)] == [d, d]
