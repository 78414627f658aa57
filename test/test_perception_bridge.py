"""Exact HMC under linear constraints and the constrained Brownian-bridge occlusion basis."""

import numpy as np
import pytest

from tactile_dock_ros.perception.bridge import (
    bridge_covariance,
    occlusion_columns,
    sample_truncated_gaussian,
)


def test_half_normal_moments():
    rng = np.random.default_rng(1)
    z = sample_truncated_gaussian(np.array([[1.0]]), np.zeros(1), np.full((4000, 1), 0.5), 4, rng)
    assert np.all(z >= 0)
    assert abs(z.mean() - np.sqrt(2 / np.pi)) < 0.04
    assert abs(z.var() - (1 - 2 / np.pi)) < 0.04


def test_matches_rejection_sampling_in_a_wedge():
    """Two oblique constraints with offsets, one not through the origin."""
    F = np.array([[1.0, 0.5], [-0.3, 1.0]])
    g = np.array([0.2, -0.1])
    rng = np.random.default_rng(2)
    z = sample_truncated_gaussian(F, g, np.tile([0.5, 0.5], (4000, 1)), 5, rng)
    assert np.all(z @ F.T + g >= -1e-9)
    ref = rng.standard_normal((200_000, 2))
    ref = ref[np.all(ref @ F.T + g >= 0, axis=1)]
    np.testing.assert_allclose(z.mean(axis=0), ref.mean(axis=0), atol=0.05)
    np.testing.assert_allclose(np.cov(z.T), np.cov(ref.T), atol=0.06)


def test_rejects_infeasible_start_and_is_deterministic():
    F, g = np.eye(2), np.zeros(2)
    with pytest.raises(ValueError, match="violates"):
        sample_truncated_gaussian(F, g, np.array([[1.0, -1.0]]), 1, np.random.default_rng(0))
    start = np.ones((10, 2))
    a = sample_truncated_gaussian(F, g, start, 3, np.random.default_rng(5))
    b = sample_truncated_gaussian(F, g, start, 3, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)


def test_bridge_covariance_is_a_brownian_bridge():
    cov = bridge_covariance(3, 2.0, 0.5)
    # s = 1/4, 1/2, 3/4: var = sigma^2 L s (1 - s)
    np.testing.assert_allclose(np.diag(cov), 0.25 * 2.0 * np.array([3, 4, 3]) / 16)
    assert cov[0, 2] == pytest.approx(0.25 * 2.0 * 0.25 * 0.25)


def test_occlusion_mean_lies_on_the_hidden_side_and_basis_spans_the_spread():
    a, b = np.array([0.07, 0.08]), np.array([0.0, 0.1])
    rng = np.random.default_rng(3)
    mean, basis = occlusion_columns(a, b, 8, 0.3, 5, 400, 6, rng)
    normal = np.array([-(b - a)[1], (b - a)[0]])
    assert mean.shape == (8, 2) and basis.shape == (16, 5)
    assert np.all((mean - a) @ normal > 0)  # bulges to the left of a -> b (the solid side)
    # The middle vertex spreads most, as in a bridge; the basis is ordered by variance.
    var = np.sum(basis.reshape(8, 2, 5) ** 2, axis=(1, 2))
    assert var.argmax() in (3, 4)
    assert np.all(np.diff(np.linalg.norm(basis, axis=0)) <= 1e-12)
    with pytest.raises(ValueError, match="distinct"):
        occlusion_columns(a, a, 8, 0.3, 5, 10, 1, rng)
