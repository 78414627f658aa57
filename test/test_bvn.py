"""bvn.quadrant against scipy's bivariate normal CDF, identities and bad input."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr
from scipy.stats import multivariate_normal

from tactile_dock_ros.core import bvn

RHOS = [
    -0.999,
    -0.99,
    -0.95,
    -0.925,
    -0.9,
    -0.75,
    -0.5,
    -0.3,
    -0.1,
    0.0,
    0.1,
    0.3,
    0.5,
    0.75,
    0.9,
    0.925,
    0.95,
    0.99,
    0.999,
]


def _scipy_quadrant(h, k, rho):
    return multivariate_normal(mean=[0.0, 0.0], cov=[[1.0, rho], [rho, 1.0]]).cdf([h, k])


def test_matches_scipy_on_grid():
    rng = np.random.default_rng(1)
    limits = np.concatenate([[-8.0, -5.0, -2.0, 0.0, 1.5, 4.0, 8.0], rng.uniform(-8, 8, 3)])
    h, k, r = np.meshgrid(limits, limits, RHOS, indexing="ij")
    ours = bvn.quadrant(h, k, r)
    ref = np.array([_scipy_quadrant(*v) for v in zip(h.ravel(), k.ravel(), r.ravel(), strict=True)])
    assert ours.shape == h.shape
    assert np.max(np.abs(ours.ravel() - ref)) <= 1e-10


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-8, 8),
    st.floats(-8, 8),
    st.floats(-0.999, 0.999),
)
def test_matches_scipy_random(h, k, rho):
    assert abs(bvn.quadrant(h, k, rho) - _scipy_quadrant(h, k, rho)) <= 1e-10


@settings(max_examples=60, deadline=None)
@given(st.floats(-8, 8), st.floats(-8, 8), st.floats(-1, 1))
def test_symmetry_identities(h, k, rho):
    p = bvn.quadrant(h, k, rho)
    assert bvn.quadrant(k, h, rho) == pytest.approx(p, abs=1e-14)  # exchangeability
    # P(X <= h, Y <= k) + P(X <= h, Y > k) = Phi(h), and P(X<=h, -Y < -k) has correlation -rho.
    assert p + bvn.quadrant(h, -k, -rho) == pytest.approx(ndtr(h), abs=1e-13)
    assert 0.0 <= p <= min(ndtr(h), ndtr(k)) + 1e-15


def test_rho_zero_factorizes_and_limits():
    h = np.linspace(-8, 8, 41)
    assert np.allclose(bvn.quadrant(h, h[::-1], 0.0), ndtr(h) * ndtr(h[::-1]), atol=1e-15)
    assert np.allclose(bvn.quadrant(h, 0.3, 1.0), ndtr(np.minimum(h, 0.3)), atol=1e-15)
    assert np.allclose(
        bvn.quadrant(h, 0.3, -1.0), np.maximum(ndtr(h) + ndtr(0.3) - 1.0, 0.0), atol=1e-15
    )
    # Continuity at the rho = +-1 limits and across the branch points 0.3, 0.75, 0.925.
    for r in (0.3, 0.75, 0.925):
        assert np.allclose(bvn.quadrant(h, -0.7, r), bvn.quadrant(h, -0.7, r - 1e-9), atol=1e-8)
    assert np.allclose(bvn.quadrant(h, 0.3, 1 - 1e-12), ndtr(np.minimum(h, 0.3)), atol=1e-5)


def test_limits_beyond_the_tail_cut_match_scipy():
    """|h| or |k| beyond 8.5 skip the quadrature (univariate limit): still within 1e-16."""
    limits = np.array(
        [-40.0, -9.0, -8.5000001, -8.4999999, -7.0, 0.5, 7.0, 8.4999999, 8.5000001, 12.0]
    )
    h, k, r = np.meshgrid(limits, limits, [-0.999, -0.6, 0.0, 0.4, 0.95], indexing="ij")
    ours = bvn.quadrant(h, k, r)
    ref = np.array([_scipy_quadrant(*v) for v in zip(h.ravel(), k.ravel(), r.ravel(), strict=True)])
    assert np.max(np.abs(ours.ravel() - ref)) <= 1e-16


def test_infinite_limits():
    assert bvn.quadrant(np.inf, 0.5, 0.7) == pytest.approx(ndtr(0.5), abs=1e-15)
    assert bvn.quadrant(-0.2, np.inf, -0.7) == pytest.approx(ndtr(-0.2), abs=1e-15)
    assert bvn.quadrant(-np.inf, 3.0, 0.2) == 0.0
    assert bvn.quadrant(np.inf, np.inf, 0.2) == 1.0


@pytest.mark.parametrize(
    "args", [(np.nan, 0.0, 0.1), (0.0, np.nan, 0.1), (0.0, 0.0, np.nan), (0.0, 0.0, 1.5)]
)
def test_bad_input(args):
    with pytest.raises(ValueError):
        bvn.quadrant(*args)


def test_far_tails_with_strong_correlation_are_exact_and_warning_free():
    """|h k| in the thousands (a far-away edge) must not overflow inside the expansion."""
    h = np.array([-2000.0, 50.0, -40.0])
    k = np.array([2000.0, -60.0, 45.0])
    rho = np.array([0.95, -0.97, 0.99])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        p = bvn.quadrant(h, k, rho)
    np.testing.assert_array_equal(p, [0.0, 0.0, 0.0])
