"""Probabilistic simulation (Sec. V-A, App. B) against Monte Carlo of the simulator."""

import numpy as np
import pytest

from tactile_dock_ros.core import problems, probsim, simulate
from tactile_dock_ros.core.geometry2d import cross
from tactile_dock_ros.core.shape import GaussianShape

DOWN = np.array([0.0, -1.0])


def _random_shape(rng, n, closed=False):
    xs = np.linspace(0.5, -0.5, n) + rng.uniform(-0.02, 0.02, n)
    ys = np.cumsum(rng.normal(0.0, 0.08, n))
    mean = np.stack([xs, ys], 1).ravel()
    basis = np.column_stack(
        [np.tile([0.01, 0.0], n), np.tile([0.0, 0.01], n)]
        + [rng.normal(0.0, 0.01, 2 * n) for _ in range(4)]
    )
    return GaussianShape(mean, basis, closed, 0.5)


def _vertical_path(shape, x):
    ys = shape.mean_vertices[:, 1]
    return np.array([[x, ys.max() + 0.3], [x, ys.min() - 0.3]])


@pytest.mark.parametrize("compliant", [True, False])
def test_dock_probability_matches_monte_carlo(compliant):
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(8):
        shape = _random_shape(rng, int(rng.integers(5, 10)))
        path = _vertical_path(shape, rng.uniform(-0.4, 0.4))
        samples = shape.vertices(shape.sample_z(rng, 20000))
        mc = simulate.monte_carlo_dock_probability(samples, False, path, 0.5, DOWN, compliant)
        est = probsim.dock_probability(shape, path, DOWN, compliant)
        assert est.p_dock == pytest.approx(est.p_stop_vertex.sum() + est.p_stop_edge.sum())
        errors.append(abs(est.p_dock - mc))
    assert np.mean(errors) <= 0.05


def test_problem_sites_match_monte_carlo_and_compliance_helps():
    rng = np.random.default_rng(2)
    prob = problems.get("notch")
    shape = prob.prior
    mv = shape.mean_vertices
    mid = 0.5 * (mv[shape.edges[:, 0]] + mv[shape.edges[:, 1]])
    starts, ends = mid - 0.15 * prob.load, mid + 0.15 * prob.load
    samples = shape.vertices(shape.sample_z(rng, 20000))
    for compliant in (True, False):
        est = probsim.dock_probabilities(shape, starts, ends, prob.load, compliant)[0]
        mc = np.array(
            [
                simulate.monte_carlo_dock_probability(
                    samples, False, [a, b], 0.5, prob.load, compliant
                )
                for a, b in zip(starts, ends, strict=True)
            ]
        )
        assert np.mean(np.abs(est - mc)) <= 0.05
        if compliant:
            rigid_est = probsim.dock_probabilities(shape, starts, ends, prob.load, False)[0]
            assert np.all(est >= rigid_est - 1e-12)
            assert np.max(est - rigid_est) > 0.2  # sliding into the hidden notch


def test_collision_probability_methods_against_monte_carlo():
    rng = np.random.default_rng(4)
    shape = _random_shape(rng, 6)
    path = _vertical_path(shape, 0.05)
    samples = shape.vertices(shape.sample_z(rng, 20000))
    c, d = samples[:, shape.edges[:, 0]], samples[:, shape.edges[:, 1]]
    move = path[1] - path[0]
    den = cross(d - c, move)
    s = cross(d - c, c - path[0]) / den
    t = cross(move, c - path[0]) / den
    mc = np.mean((den > 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1), axis=0)
    for method in probsim.METHODS:
        p = probsim.collision_probabilities(path[0], path[1], shape, method)
        assert p.shape == (shape.n_edges,)
        assert np.max(np.abs(p - mc)) <= 0.1, method


def test_deterministic_shape_gives_exact_limits():
    flat = GaussianShape(np.array([1.0, 0.0, 0.0, 0.0, -1.0, 0.0]), np.zeros((6, 0)), False, 0.5)
    for method in probsim.METHODS:
        p = probsim.collision_probabilities([0.5, 1.0], [0.5, -1.0], flat, method)
        assert p.tolist() == [1.0, 0.0]
    est = probsim.dock_probability(flat, [[0.5, 1.0], [0.5, -1.0]], DOWN)
    assert est.p_dock == 1.0 and est.p_stop_edge.tolist() == [1.0, 0.0]
    slope = GaussianShape(np.array([1.0, 1.0, 0.0, 0.0, -0.2, 1.0]), np.zeros((6, 0)), False, 0.5)
    comp = probsim.dock_probability(slope, [[0.5, 2.0], [0.5, 0.0]], DOWN, compliant=True)
    rigid = probsim.dock_probability(slope, [[0.5, 2.0], [0.5, 0.0]], DOWN, compliant=False)
    assert comp.p_dock == 1.0 and comp.p_stop_vertex.tolist() == [0.0, 1.0, 0.0]
    # it arrived at vertex 1 by a right slide (along l(v), toward the edge's last vertex)
    assert comp.p_stop_vertex_sides.tolist() == [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    assert rigid.p_dock == 0.0


def test_rank_deficient_and_prefix():
    rng = np.random.default_rng(5)
    shape = _random_shape(rng, 6)
    thin = GaussianShape(shape.mean, shape.basis[:, :1], False, 0.5)  # rank 1 covariance
    est = probsim.dock_probability(thin, _vertical_path(thin, 0.1), DOWN)
    assert np.isfinite(est.p_dock) and np.all(np.isfinite(est.p_stop_vertex))
    # A prefix straight through the terrain makes docking (nearly) impossible.
    path = _vertical_path(shape, 0.1)
    through = np.array([path[0], path[1], path[1] + [0.01, 0.0], path[0] + [0.01, 0.0]])
    blocked = probsim.dock_probability(shape, np.vstack([through, path[1]]), DOWN)
    assert blocked.p_prefix_clear < 0.05 and blocked.p_dock < 0.05


def test_bad_input():
    rng = np.random.default_rng(6)
    shape = _random_shape(rng, 5)
    assert np.all(probsim.collision_probabilities([0.0, 1.0], [0.0, 1.0], shape) == 0.0)
    assert probsim.dock_probability(shape, [[0.0, 1.0], [0.0, 1.0]], DOWN).p_dock == 0.0
    with pytest.raises(ValueError):
        probsim.dock_probability(shape, [[0.0, 1.0], [np.nan, 0.0]], DOWN)
    with pytest.raises(ValueError):
        probsim.dock_probability(shape, [[0.0, 1.0]], DOWN)
    with pytest.raises(ValueError):
        probsim.dock_probability(shape, [[0.0, 1.0], [0.0, 0.0]], [0.0, 0.0])
    with pytest.raises(ValueError):
        probsim.collision_probabilities([0.0, 1.0], [0.0, 0.0], shape, method="nope")
    with pytest.raises(TypeError):
        probsim.collision_probabilities([0.0, 1.0], [0.0, 0.0], shape.mean)


@pytest.mark.parametrize("cyclic", [False, True])
def test_solve_chain_matches_dense(cyclic):
    rng = np.random.default_rng(8)
    a, b = rng.uniform(0, 1, (3, 13)), rng.uniform(0, 0.9, (3, 13))
    x = probsim.solve_chain(a, b, cyclic)
    for k in range(3):
        m = np.eye(13) - np.diag(b[k, :-1], 1)
        if cyclic:
            m[-1, 0] = -b[k, -1]
        assert np.allclose(m @ x[k], a[k])
    # One coefficient row shared by several right-hand sides (broadcast) gives the same.
    shared = probsim.solve_chain(a, b[:1], cyclic)
    assert shared.shape == a.shape
    assert np.allclose(shared, probsim.solve_chain(a, np.repeat(b[:1], 3, axis=0), cyclic))


def test_closed_shape_matches_monte_carlo():
    rng = np.random.default_rng(9)
    angles = np.linspace(0, 2 * np.pi, 7)[:-1] + 0.3
    mean = np.stack([0.3 * np.cos(angles), 0.3 * np.sin(angles)], 1).ravel()  # CCW hexagon
    basis = np.column_stack(
        [np.tile([0.02, 0.0], 6), np.tile([0.0, 0.02], 6)]
        + [rng.normal(0, 0.01, 12) for _ in range(3)]
    )
    shape = GaussianShape(mean, basis, True, 0.4)
    samples = shape.vertices(shape.sample_z(rng, 20000))
    for x in (-0.2, 0.0, 0.15):
        path = [[x, 1.0], [x, -1.0]]
        mc = simulate.monte_carlo_dock_probability(samples, True, path, 0.4, DOWN)
        assert probsim.dock_probability(shape, path, DOWN).p_dock == pytest.approx(mc, abs=0.05)


@pytest.mark.parametrize("name", ["notch", "three_ledges"])
def test_pruning_loses_only_negligible_events(name, monkeypatch):
    """The sequential fast path (bounds before the orthant) against evaluating every event."""
    prob = problems.get(name)
    shape = prob.prior
    mv = shape.mean_vertices
    mid = 0.5 * (mv[shape.edges[:, 0]] + mv[shape.edges[:, 1]])
    starts, ends = mid - 0.3 * prob.load, mid + 0.3 * prob.load
    pruned = probsim.dock_probabilities(shape, starts, ends, prob.load)
    # PRUNE_BELOW <= 0 keeps every (move, edge, event) except those with an impossible condition.
    monkeypatch.setattr(probsim, "PRUNE_BELOW", -1.0)
    full = probsim.dock_probabilities(shape, starts, ends, prob.load)
    for fast, slow in zip(pruned, full, strict=True):
        assert np.max(np.abs(fast - slow)) <= 1e-9
    assert np.max(full[0]) > 0.5  # the comparison covers likely docks, not only zeros


@pytest.mark.parametrize("name", ["sloper", "notch"])
def test_pooled_event_orthants_match_explicit_blocks(name, monkeypatch):
    """The events' 6 x 6 covariances read from the shared pair / edge pool (``column_at``) give
    what the Mendell-Elston orthant gives on explicitly built blocks, for every (move, edge)."""
    monkeypatch.setattr(probsim, "PRUNE_BELOW", -1.0)  # every event goes through the orthant
    prob = problems.get(name)
    shape = prob.prior
    mv = shape.mean_vertices
    mid = 0.5 * (mv[shape.edges[:, 0]] + mv[shape.edges[:, 1]])
    starts, ends = mid - 0.3 * prob.load, mid + 0.3 * prob.load
    means, covs = shape.edge_gaussians()
    pooled = probsim._contact_events_sequential(starts, ends, shape, prob.load, means, covs)
    values, grads = probsim._conditions(
        starts[:, None], ends[:, None], means[None, :, :2], means[None, :, 2:]
    )
    w = simulate.friction_functionals(prob.load, shape.friction)[probsim._FRICTION_ROWS]
    w = w * probsim._FRICTION_SIGNS[:, None]
    fric_grad = np.concatenate([-w, w], axis=1)
    g9 = np.concatenate([grads, np.broadcast_to(fric_grad, (*grads.shape[:2], 5, 4))], axis=2)
    c9 = g9 @ covs[None] @ np.swapaxes(g9, 2, 3)  # (K, E, 9, 9)
    fric_mean = ((means[:, 2:] - means[:, :2]) @ w.T).T[:, None]  # (5, 1, E)
    v9 = np.concatenate([values, np.broadcast_to(fric_mean, (5, *values.shape[1:]))])
    for slot, pick in enumerate(probsim._EVENT_PICK):
        block = np.moveaxis(c9[:, :, pick][:, :, :, pick], (2, 3), (0, 1))  # (6, 6, K, E)
        explicit = probsim.positive_orthant_sequential(v9[pick], block)
        assert np.max(np.abs(pooled[slot] - explicit)) <= 1e-12
    assert np.max(pooled) > 0.3  # likely events are covered, not only zeros
