"""The ground truth's own step error (docs/simulator.md, "The ground truth's own error"): what
two odometries share on a slice, the trajectory's white noise, and that error drawn onto the
simulated side's step errors."""

from __future__ import annotations

import numpy as np
import pytest

from studies.realism.ground_truth import shared_error, twists, white_noise


def test_the_error_two_odometries_share_is_the_ground_truths() -> None:
    """Two odometries with independent own errors a, b (4 mm a step) on top of one ground-truth
    error g: the shared model's mean is g, with no shared variance; errors drawn from it average
    g. Opposite errors (g and -g) are not shared."""
    rng = np.random.default_rng(0)
    g = np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.001])  # what the ground truth gets wrong
    a, b = rng.normal(0, 0.004, (200, 6)), rng.normal(0, 0.004, (200, 6))
    shared = shared_error(g + a, g + b, np.full(6, 1e-4))
    np.testing.assert_allclose(shared.mean, g, atol=1e-3)
    assert shared.rms_t_cm == pytest.approx(1.0, abs=0.15)
    assert max(shared.variance) <= 1e-8  # independent errors share no variance
    # errors the two do not agree on are not the ground truth's
    assert shared_error(a + g, b - g, np.full(6, 1e-4)).rms_t_cm < 0.2
    E = np.tile(np.eye(4), (5000, 1, 1))
    drawn = twists(shared.compose(E, rng))
    np.testing.assert_allclose(drawn.mean(axis=0), shared.mean, atol=3e-4)


def test_the_white_noise_of_a_trajectory() -> None:
    """3 mm of white noise along x on a straight 1 m a frame drive; none on an exact one."""
    rng = np.random.default_rng(0)
    noisy = np.tile(np.eye(4), (400, 1, 1))
    noisy[:, 0, 3] = np.arange(400) * 1.0 + rng.normal(0.0, 0.003, 400)
    expected = 100 * 1.538 * np.sqrt(2.0) * 0.003 / np.sqrt(3.0)  # per-axis RMS of (3, 0, 0)
    assert white_noise(noisy)[0] == pytest.approx(expected, rel=0.25)
    exact = np.tile(np.eye(4), (11, 1, 1))
    exact[:, 0, 3] = np.arange(11) * 1.2
    assert white_noise(exact)[0] < 1e-6
