"""Constraints g1..g6 against exact geometric predicates (shapely, orientation tests)."""

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.constraints import (
    PairStructure,
    collision_bounds,
    crossed_free_pairs,
    history_consistent,
    observation_primitives,
    observation_violations,
    pair_values,
    prune_pairs,
)
from tactile_dock_ros.core.history import History, Status

coord = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
point = st.tuples(coord, coord)


def cross(u, v):
    return u[0] * v[1] - u[1] * v[0]


def orient(p, q, r):
    return cross(np.subtract(q, p), np.subtract(r, p))


def generic(a, b, c, d, tol=1e-6):
    """No three points (nearly) collinear: predicates are then unambiguous."""
    return (
        all(abs(orient(*tri)) > tol for tri in ((a, b, c), (a, b, d), (c, d, a), (c, d, b)))
        and np.hypot(*np.subtract(b, a)) > 1e-3
    )


def g_values(a, b, c, d, status, mu):
    history = History([a], [b], [status])
    sign, lin, const, active = observation_primitives(history, mu)
    y = np.array([[[*c, *d]]])
    return pair_values(y, sign, lin, const, active)[0, 0]


@settings(max_examples=2000, deadline=None)
@given(point, point, point, point)
def test_g1_to_g4_match_shapely_crossing_and_direction(a, b, c, d):
    if not generic(a, b, c, d):
        return
    g = g_values(a, b, c, d, Status.COLLIDE, 0.5)[:4]
    crosses = shapely.LineString([a, b]).intersects(shapely.LineString([c, d]))
    # the tool enters the solid (left of cd) iff a is right of cd and b left of it
    entering = crosses and orient(c, d, a) < 0 < orient(c, d, b)
    assert bool(np.all(g <= 0)) == entering
    assert bool(np.all(g <= 0) or np.all(g >= 0)) == crosses


def in_cone(v, lo, hi):
    """v strictly inside the cone swept CCW from lo to hi (opening < pi)."""
    return cross(lo, v) > 0 and cross(v, hi) > 0


@settings(max_examples=1000, deadline=None)
@given(point, point, point, point, st.floats(0.05, 2.0))
def test_g5_g6_match_friction_cone_by_angles(a, b, c, d, mu):
    if not generic(a, b, c, d) or np.hypot(*np.subtract(d, c)) < 1e-3:
        return
    e = np.subtract(d, c) / np.hypot(*np.subtract(d, c))
    n = np.array([e[1], -e[0]])  # outward normal: right of travel c -> d
    push = np.subtract(a, b)
    # classify the reversed motion by its angle to the outward normal
    ang = np.arctan2(cross(n, push), np.dot(n, push))  # CCW from n
    half = np.arctan(mu)
    if abs(abs(ang) - half) < 1e-6 or abs(abs(ang) - np.pi / 2) < 1e-6:
        return
    expected = {
        Status.STICK: abs(ang) < half,
        Status.SLIP_LEFT: half < ang < np.pi / 2,
        Status.SLIP_RIGHT: -np.pi / 2 < ang < -half,
    }
    for status, inside in expected.items():
        g = g_values(a, b, c, d, status, mu)[4:]
        assert bool(np.all(g <= 0)) == inside, status
    assert in_cone(push, n - mu * e, n + mu * e) == expected[Status.STICK]


def brute_force_consistent(vertices, closed, history, mu):
    """Reference f_H: loop over observations and edges with shapely and orientation tests."""
    n = len(vertices)
    edges = [(i, (i + 1) % n) for i in range(n if closed else n - 1)]
    for a, b, s in zip(history.a, history.b, history.status, strict=True):
        seg = shapely.LineString([a, b])
        hits = []
        for u, v in edges:
            c, d = vertices[u], vertices[v]
            if not seg.intersects(shapely.LineString([c, d])):
                continue
            hits.append((c, d))
        if s == Status.FREE:
            if hits:
                return False
            continue
        ok = False
        for c, d in hits:
            if not orient(c, d, a) < 0 < orient(c, d, b):
                continue
            g = g_values(a, b, c, d, s, mu)
            ok |= bool(np.all(g <= 0))
        if not ok:
            return False
    return True


def test_history_consistent_matches_brute_force_on_random_polygons():
    rng = np.random.default_rng(3)
    checked = 0
    for trial in range(150):
        n = int(rng.integers(3, 8))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radius = rng.uniform(0.3, 1.0, n)
        poly = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
        k = int(rng.integers(1, 4))
        a = rng.uniform(-1.2, 1.2, (k, 2))
        b = a + rng.normal(0, 0.6, (k, 2))
        status = rng.integers(0, 5, k)
        history = History(a, b, status)
        got = history_consistent(True, poly[None], history, 0.4)[0]
        assert got == brute_force_consistent(poly, True, history, 0.4), trial
        checked += got
    assert checked > 5  # the positive branch is exercised too


def test_crossed_free_pairs_are_the_free_segments_crossing_an_edge():
    """Every (free observation, edge) pair some polygon of the batch crosses, and no other pair
    (contact rows are never listed), against shapely on random polygons and segments."""
    rng = np.random.default_rng(5)
    listed = 0
    for trial in range(60):
        n, k = int(rng.integers(3, 8)), int(rng.integers(1, 6))
        angles = np.sort(rng.uniform(0, 2 * np.pi, (2, n)), axis=1)
        radius = rng.uniform(0.3, 1.0, (2, n))
        polys = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=-1)
        a = rng.uniform(-1.2, 1.2, (k, 2))
        b = a + rng.normal(0, 0.6, (k, 2))
        history = History(a, b, rng.choice([Status.FREE, Status.STICK], k))
        got = crossed_free_pairs(True, polys, history)
        expected = []
        for o in range(k):
            for e in range(n):
                ends = [poly[[e, (e + 1) % n]] for poly in polys]
                if not all(generic(a[o], b[o], *end) for end in ends):
                    continue
                seg = shapely.LineString([a[o], b[o]])
                hit = any(seg.intersects(shapely.LineString(end)) for end in ends)
                if hit and history.status[o] == Status.FREE:
                    expected.append((o, e))
        generic_rows = {tuple(p) for p in got.tolist()}
        assert set(expected) <= generic_rows, trial
        for o, e in generic_rows - set(expected):  # only degenerate (near-collinear) extras
            ends = [poly[[e, (e + 1) % n]] for poly in polys]
            assert not all(generic(a[o], b[o], *end) for end in ends), trial
        assert np.all(np.diff(got[:, 0] * n + got[:, 1]) > 0)  # row order, no repeats
        listed += len(got)
    assert listed > 20
    empty = crossed_free_pairs(True, np.zeros((0, 3, 2)), History([[0, 0]], [[1, 0]], [0]))
    assert empty.shape == (0, 2)


def test_history_consistent_batches_and_open_polylines():
    problem = problems.get("sloper")
    rng = np.random.default_rng(0)
    truths = problem.prior.vertices(problem.prior.sample_z(rng, 40))
    history = History([[0.0, 0.45]], [[0.0, -0.5]], [Status.FREE])  # goes through the solid
    assert not history_consistent(False, truths, history, 0.5).any()
    above = History([[0.0, 0.45]], [[0.1, 0.45]], [Status.FREE])
    assert history_consistent(False, truths, above, 0.5).all()
    assert history_consistent(False, truths, History(), 0.5).all()


def test_bad_inputs_raise():
    history = History([[0.0, 0.0]], [[1.0, 0.0]], [Status.FREE])
    verts = np.zeros((1, 4, 2))
    verts[0, 2, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        history_consistent(False, verts, history, 0.5)
    with pytest.raises(ValueError, match="shape"):
        history_consistent(False, np.zeros((3, 1, 2)), history, 0.5)
    with pytest.raises(ValueError, match="friction"):
        history_consistent(False, np.zeros((1, 4, 2)), history, -1.0)
    with pytest.raises(ValueError, match="zero length"):
        History([[0.0, 0.0]], [[0.0, 0.0]], [Status.COLLIDE])


def test_zero_length_edges_never_collide_with_a_segment_off_their_point():
    verts = np.array([[[0.5, 0.5], [0.5, 0.5], [0.2, 0.9]]])  # first edge has zero length
    history = History([[0.0, 0.0]], [[1.0, 0.0]], [Status.FREE])
    assert history_consistent(False, verts, history, 0.5)[0]


def test_pair_structure_empty_groups():
    status = np.array([Status.FREE, Status.COLLIDE])
    structure = PairStructure(status, np.zeros((0, 2), dtype=int))
    out = structure.reduce(np.zeros((0, 6)))
    assert out[0] == -np.inf and out[1] == np.inf


def test_collision_bound_dominates_monte_carlo_frequency_and_prunes():
    problem = problems.get("three_ledges")
    shape = problem.prior
    rng = np.random.default_rng(5)
    a = np.array([[-0.5, 0.7], [0.1, 0.7], [-0.3, 0.6]])
    b = np.array([[-0.5, 0.2], [0.1, -0.2], [-0.3, 0.38]])
    history = History(a, b, [Status.FREE] * 3)
    bound = collision_bounds(shape, history)
    verts = shape.vertices(shape.sample_z(rng, 4000))
    ends = verts[:, shape.edges]  # (N, E, 2, 2)
    freq = np.zeros_like(bound)
    for i in range(len(history)):  # three segments; vectorized over samples and edges
        single = History(a[i : i + 1], b[i : i + 1], [Status.FREE])
        sign, lin, const, active = observation_primitives(single, shape.friction)
        y = ends.reshape(len(verts), -1, 4)
        g = pair_values(y, sign, lin, const, active)[..., :4]
        crosses = np.all(g <= 0, axis=-1) | np.all(g >= 0, axis=-1)
        freq[i] = crosses.mean(axis=0)
    se = np.sqrt(freq * (1 - freq) / 4000) + 1e-3
    assert np.all(bound >= freq - 4 * se)
    pairs = prune_pairs(shape, history, 1e-4)
    assert 0 < len(pairs) < bound.size // 3
    # every pair seen colliding in the Monte Carlo run survives pruning
    seen = np.argwhere(freq > 0)
    kept = {tuple(p) for p in pairs}
    assert all(tuple(p) in kept for p in seen)


def test_observation_violations_sign_convention():
    square = np.array([[[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]]])  # CCW
    inward = History([[2.0, 0.0]], [[0.5, 0.0]], [Status.COLLIDE])
    outward = History([[0.5, 0.0]], [[2.0, 0.0]], [Status.COLLIDE])
    assert observation_violations(True, square, inward, 0.5)[0, 0] <= 0
    assert observation_violations(True, square, outward, 0.5)[0, 0] > 0
    stick = History([[2.0, 0.0]], [[0.5, 0.0]], [Status.STICK])
    slip = History([[2.0, 0.0]], [[0.5, 0.0]], [Status.SLIP_LEFT])
    assert history_consistent(True, square, stick, 0.5)[0]
    assert not history_consistent(True, square, slip, 0.5)[0]


def test_empty_sample_batch():
    history = History([[0.0, 0.0]], [[1.0, 0.0]], [Status.FREE])
    assert observation_violations(False, np.zeros((0, 4, 2)), history, 0.5).shape == (0, 1)
