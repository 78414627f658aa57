"""Interval sets along lines / ellipses against dense evaluation; truncated-normal sampling."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.constraint_systems import HistoryConstraints, LinearConstraints
from tactile_dock_ros.core.constraints import observation_primitives, pair_values, prune_pairs
from tactile_dock_ros.core.intervals import (
    ellipse_feasible_set,
    ellipse_roots,
    line_feasible_set,
    normal_log_mass,
    quadratic_roots,
    quartic_roots,
    sample_truncated_normal,
    trig_basis,
)
from tactile_dock_ros.core.sampling import sample_posterior
from tactile_dock_ros.core.sampling_problems import probe_history

coef = st.floats(-10, 10, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(coef, coef, coef)
def test_quadratic_roots_are_roots(a, b, c):
    roots = quadratic_roots(a, b, c)
    real = roots[np.isfinite(roots)]
    scale = abs(a) + abs(b) + abs(c)
    for r in real[np.abs(real) < 1e6]:
        assert abs(a * r * r + b * r + c) <= 1e-8 * scale * (1 + r * r)
    if abs(a) > 1e-6 * scale and b * b - 4 * a * c > 1e-9 * scale**2:
        assert len(real) == 2


def test_quartic_roots_match_numpy():
    rng = np.random.default_rng(0)
    polys = rng.normal(size=(200, 5))
    got = quartic_roots(polys)
    for p, r in zip(polys, got, strict=True):
        ref = np.roots(p)
        ref = np.sort(ref[np.abs(ref.imag) < 1e-9].real)
        assert np.allclose(np.sort(r[np.isfinite(r)]), ref, atol=1e-7)
    # degenerate leading coefficient: the finite roots survive
    r = quartic_roots(np.array([[0.0, 0.0, 1.0, -3.0, 2.0]]))[0]
    assert np.allclose(np.sort(r[np.abs(r) < 1e6]), [1.0, 2.0])


def shape_system(n_probes=6, seed=1):
    problem = problems.get("notch")
    rng = np.random.default_rng(seed)
    truth = problem.sample_ground_truth(rng)
    history = probe_history(problem, truth, np.linspace(-0.25, 0.25, n_probes))
    pairs = prune_pairs(problem.prior, history, 1e-4)
    feasible_z = sample_posterior(problem.prior, history, 25, rng).z
    return problem.prior, HistoryConstraints(problem.prior, history, pairs), feasible_z, rng


def dense_feasible(system, z):
    return np.all(system.violations(system.values(z)) <= 0, axis=-1)


def check_against_dense(interval_set, ts, dense):
    """Dense points disagree only within 1e-7 of a reported boundary."""
    got = interval_set.contains(ts)
    edges = interval_set.bounds.ravel()
    for t in ts[got != dense]:
        assert edges.size and np.min(np.abs(edges - t)) < 1e-7


def test_line_interval_sets_agree_with_dense_evaluation():
    shape, system, feasible_z, rng = shape_system()
    boundaries = 0
    for z0 in feasible_z:
        d = rng.normal(size=shape.n_basis) * 0.3
        interval_set = line_feasible_set(system, z0, d, -4.0, 4.0)
        ts = np.linspace(-4, 4, 4001)
        check_against_dense(interval_set, ts, dense_feasible(system, z0 + ts[:, None] * d))
        assert interval_set.contains(np.zeros(1))[0]  # the line starts feasible
        boundaries += len(interval_set.bounds)
    assert boundaries > len(feasible_z)  # some lines leave and re-enter the feasible set


def test_ellipse_interval_sets_agree_with_dense_evaluation():
    shape, system, feasible_z, rng = shape_system()
    exits = 0
    for z0 in feasible_z:
        p = rng.normal(size=shape.n_basis)
        interval_set = ellipse_feasible_set(system, z0, p, np.pi / 2)
        assert interval_set.contains(np.zeros(1))[0]
        ts = np.linspace(0, np.pi / 2, 4001)
        path = z0 * np.cos(ts)[:, None] + p * np.sin(ts)[:, None]
        check_against_dense(interval_set, ts, dense_feasible(system, path))
        exits += interval_set.measure < np.pi / 2 - 1e-9
        # the trigonometric coefficients reproduce the primitive values
        coef = system.ellipse_coefficients(z0[None], p[None])[0]
        g = trig_basis(ts[::400]) @ coef
        assert np.allclose(g, system.values(path[::400]), atol=1e-12)
    assert exits > 0


def test_primitive_values_match_the_direct_pair_evaluation():
    """The system's per-edge quadratic terms, gathered to the pairs, give every pair's g1..g6
    as evaluated directly on its own edge coordinates; so do its line coefficients."""
    shape, system, feasible_z, rng = shape_system()
    pairs = system.structure.pairs
    assert len(np.unique(pairs[:, 1])) < len(pairs) / 2  # most edges serve several pairs
    z = np.vstack([feasible_z, rng.normal(size=(10, shape.n_basis))])
    d = rng.normal(size=z.shape)

    def direct(z):
        sign, lin, const, active = observation_primitives(system.history, shape.friction)
        y = shape.states(z)[:, shape.edge_rows()[pairs[:, 1]]]  # (N, P, 4)
        obs = pairs[:, 0]
        return system.structure.pair_values(
            pair_values(y, sign[obs], lin[obs], const[obs], active[obs])
        )

    assert np.allclose(system.pair_violations(z), direct(z), atol=1e-12)
    coef = system.line_coefficients(z, d)  # (N, K, 3): q0 + q1 t + q2 t^2
    g = coef[..., 0] + 0.7 * coef[..., 1] + 0.49 * coef[..., 2]
    assert np.allclose(system.pair_values_of(g), direct(z + 0.7 * d), atol=1e-12)


def test_linear_system_ellipse_roots():
    system = LinearConstraints(np.array([[1.0, 0.0]]), np.array([-1.0]))  # z1 <= 1
    z0, p = np.array([[0.0, 0.0]]), np.array([[2.0, 0.0]])  # z1(t) = 2 sin t
    roots, owner = ellipse_roots(
        system.ellipse_coefficients(z0, p), np.ones((1, 1), bool), system.linear, [np.pi / 2]
    )
    assert np.allclose(roots[0], [np.pi / 6]) and owner[0, 0] == 0


@pytest.mark.parametrize("a,b", [(-np.inf, 0.0), (1.0, 2.0), (8.0, 9.0), (-40.0, -39.0)])
def test_normal_log_mass_matches_scipy_and_tails(a, b):
    ref = np.log(stats.norm.cdf(b) - stats.norm.cdf(a)) if -8 < b < 5 else None
    got = normal_log_mass(np.array([a]), np.array([b]))[0]
    if ref is not None and np.isfinite(ref):
        assert np.isclose(got, ref, rtol=1e-10)
    if a >= 0:  # upper tail: via survival functions
        expected = stats.norm.logsf(a) + np.log1p(
            -np.exp(stats.norm.logsf(b) - stats.norm.logsf(a))
        )
    else:  # lower tail: via the CDF
        expected = stats.norm.logcdf(b) + np.log1p(
            -np.exp(stats.norm.logcdf(a) - stats.norm.logcdf(b))
        )
    assert np.isfinite(got) and np.isclose(got, expected, rtol=1e-8)


def test_truncated_normal_on_union_matches_moments_and_tails():
    rng = np.random.default_rng(4)
    n = 20000
    edges = np.tile([-1.0, 0.5, 1.0, 3.0], (n, 1))
    ok = np.tile([True, False, True], (n, 1))
    x, found = sample_truncated_normal(edges, ok, np.zeros(n), np.ones(n), rng)
    assert found.all()
    assert np.all(((x >= -1) & (x <= 0.5)) | ((x >= 1) & (x <= 3)))
    grid = np.linspace(-1, 3, 400001)
    dens = stats.norm.pdf(grid) * ((grid <= 0.5) | (grid >= 1))
    dens /= np.trapezoid(dens, grid)
    mean = np.trapezoid(grid * dens, grid)
    var = np.trapezoid((grid - mean) ** 2 * dens, grid)
    assert abs(x.mean() - mean) < 4 * np.sqrt(var / n)
    assert abs(x.var() - var) < 0.03
    # far tail: [30, 31] with mean 0 is sampled without NaN, near 30 + 1/30
    edges = np.tile([30.0, 31.0], (1000, 1))
    y, found = sample_truncated_normal(
        edges, np.ones((1000, 1), bool), np.zeros(1000), np.ones(1000), rng
    )
    assert found.all() and np.all((y >= 30) & (y <= 31))
    assert abs(y.mean() - 30 - 1 / 30) < 0.01
    # nothing feasible: reported, not invented
    y, found = sample_truncated_normal(
        edges[:3], np.zeros((3, 1), bool), np.zeros(3), np.ones(3), rng
    )
    assert not found.any() and np.isnan(y).all()


@pytest.mark.parametrize("lead", [1.0, 2e-3, 1e-7])
def test_quartic_roots_in_a_window_from_known_roots(lead):
    """Closed form with its fallbacks: quartics built from known roots (distinct, double,
    symmetric biquadratic, with a complex pair), times (1 + lead x): a small leading coefficient
    puts a root far out (closed form down to 1e-3, then companion eigenvalues)."""
    rng = np.random.default_rng(5)
    cases = []
    for _ in range(400):
        kind = rng.integers(4)
        if kind == 0:
            roots = rng.uniform(-1, 1, 3)
        elif kind == 1:  # a double root, apart from the simple one
            r = rng.uniform(-0.8, -0.1), rng.uniform(0.1, 0.8)
            roots = np.array([r[0], r[0], r[1]])
        elif kind == 2:  # with -1/lead: biquadratic (q = 0 in the depressed form) for lead 1
            a = rng.uniform(0.1, 0.8)
            roots = np.array([a, -a, 1.0 / lead])
        else:  # a real root and a complex pair
            roots = np.array([rng.uniform(-1, 1), 0.3 + 0.5j, 0.3 - 0.5j])
        poly = np.real(np.polymul(np.poly(roots), [lead, 1.0]))
        cases.append((poly, np.append(roots, -1.0 / lead), kind == 1))
    got = quartic_roots(np.array([c[0] for c in cases]), (-0.9, 0.95))
    for (_, roots, double), r in zip(cases, got, strict=True):
        real = np.real(roots[np.abs(np.imag(roots)) < 1e-12])
        want = real[(real > -0.9) & (real < 0.95)]
        found = r[(r > -0.9) & (r < 0.95)]
        tol = 1e-4 if double else 1e-8  # a double root is ill-conditioned for any method
        # every root in the window is found, and nothing else (a double root may split)
        assert all(np.min(np.abs(found - w), initial=np.inf) < tol for w in want)
        assert all(np.min(np.abs(want - f)) < tol for f in found)
