"""Deterministic compliant simulator: hand-built cases, observations, eq. (19), feasibility."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core import explore, problems, simulate, slides
from tactile_dock_ros.core.geometry2d import cross, outward_normal, perp
from tactile_dock_ros.core.history import Status
from tactile_dock_ros.core.simulate import Feature

DOWN = np.array([0.0, -1.0])
MU = 0.5
FLAT = np.array([[1.0, 0.0], [-1.0, 0.0]])  # right to left: solid below
# A 45 degree slope (steeper than atan 0.5) ending in a corner against a steep wall on the left.
CORNER = np.array([[1.0, 1.0], [0.0, 0.0], [-0.2, 1.0]])
# The same slope continuing with a flat floor, with a cliff (convex turn away), or just ending.
SLOPE_FLAT = np.array([[1.0, 1.0], [0.0, 0.0], [-1.0, 0.0]])
SLOPE_CLIFF = np.array([[1.0, 1.0], [0.0, 0.0], [0.0, -1.0], [-1.0, -1.0]])
SLOPE_END = np.array([[1.0, 1.0], [0.0, 0.0]])
# A slope with a small notch half way: the tool slides into it and is trapped.
NOTCH = np.array([[1.0, 1.0], [0.1, 0.1], [0.05, 0.0], [0.0, 0.08], [-1.0, -0.92]])


def _run(vertices, path, compliant=True, load=DOWN, closed=False):
    return simulate.guarded_path(vertices, closed, np.array(path, float), MU, load, compliant, 0.01)


def test_flat_ledge_sticks():
    ex = _run(FLAT, [[0.2, 1.0], [0.2, -1.0]])
    assert ex.docked and ex.contact
    assert ex.stop_feature == Feature("edge", 0)
    assert np.allclose(ex.stop_point, [0.2, 0.0])
    obs = ex.observations
    assert obs.status.tolist() == [Status.FREE, Status.STICK]
    assert np.allclose(obs.a, [[0.2, 1.0], [0.2, 0.005]])
    assert np.allclose(obs.b, [[0.2, 0.01], [0.2, -0.005]])


def test_load_outside_cone_slips_on_flat():
    # pushing at 70 degrees from the normal exceeds atan(0.5): slides toward c (right, +x)
    load = np.array([np.sin(np.deg2rad(70)), -np.cos(np.deg2rad(70))])
    ex = _run(FLAT, [[0.0, 0.5], [0.0, 0.0] + 0.5 * load], load=load)
    assert not ex.docked
    assert ex.observations.status[-1] == Status.SLIP_LEFT
    assert ex.stop_feature == Feature("vertex", 0)  # slid to the end of the ledge and fell off


def test_steep_slope_slides_to_corner():
    ex = _run(CORNER, [[0.5, 2.0], [0.5, 0.0]])
    assert ex.docked
    assert ex.stop_feature == Feature("vertex", 1)
    assert np.allclose(ex.stop_point, [0.0, 0.0])
    assert ex.observations.status[-1] == Status.SLIP_RIGHT
    rigid = _run(CORNER, [[0.5, 2.0], [0.5, 0.0]], compliant=False)
    assert not rigid.docked and rigid.stop_feature == Feature("edge", 0)
    assert np.allclose(rigid.stop_point, [0.5, 0.5])


@pytest.mark.parametrize(
    ("shape", "docked", "vertex"),
    [(SLOPE_FLAT, True, 1), (SLOPE_CLIFF, False, 1), (SLOPE_END, False, 1)],
)
def test_vertex_between_two_edges(shape, docked, vertex):
    ex = _run(shape, [[0.5, 2.0], [0.5, 0.0]])
    assert ex.docked is docked
    assert ex.stop_feature == Feature("vertex", vertex)


def test_notch_traps_and_slope_continues():
    ex = _run(NOTCH, [[0.6, 2.0], [0.6, 0.0]])
    assert ex.docked and ex.stop_feature == Feature("vertex", 2)
    # Without the notch the tool slides past vertex 1 and off the far end of the slope.
    smooth = np.array([[1.0, 1.0], [0.1, 0.1], [-1.0, -1.0]])
    ex = _run(smooth, [[0.6, 2.0], [0.6, 0.0]])
    assert not ex.docked and ex.stop_feature == Feature("vertex", 2)


# 45 degrees down to the left, then a 53 degree edge 15 cm long, then a wall down to a floor: a
# slip on the first edge slides right over the whole second edge and separates at the wall's top
BENT_SLOPE_WALL = np.array([[0.3, 0.3], [0.18, 0.18], [0.09, 0.06], [0.09, -0.3], [-0.3, -0.3]])
BENT_LOAD_MOVE = [[0.24, 0.6], [0.24, 0.0]]  # first contact on edge 0 at (0.24, 0.24)


def _slide(vertices, path, **options):
    return simulate.guarded_path(
        vertices, False, np.array(path, float), MU, DOWN, False, 0.01, **options
    )


def test_a_non_compliant_slide_on_slip_is_evidence_along_the_face_up_to_max_slide():
    rigid = _slide(BENT_SLOPE_WALL, BENT_LOAD_MOVE)
    assert rigid.stop_feature == Feature("edge", 0) and not rigid.separated
    run = _slide(BENT_SLOPE_WALL, BENT_LOAD_MOVE, slide_on_slip=True)
    assert not run.docked and run.separated and run.stop_feature == Feature("vertex", 2)
    assert np.array_equal(run.observations.status, rigid.observations.status)  # first contact
    evidence = explore.slide_evidence(BENT_SLOPE_WALL, False, run, DOWN, 0.01)
    rows = evidence.subset(np.arange(len(rigid.observations), len(evidence)))
    # one slip row per 4 cm of the 15 cm edge 1, each crossing it (the face it slid along)
    assert len(rows) == 4 and np.all(rows.status == Status.SLIP_RIGHT)
    c, d = BENT_SLOPE_WALL[1], BENT_SLOPE_WALL[2]
    middle = 0.5 * (rows.a + rows.b)
    assert np.allclose(cross(d - c, middle - c) / np.linalg.norm(d - c), 0.0, atol=1e-9)
    gaps = np.linalg.norm(np.diff(middle, axis=0), axis=1)
    assert np.all(gaps <= slides.EVIDENCE_SPACING_M + 1e-9)
    moves = np.ones(len(evidence), int)
    assert slides.consistent_with_slides(BENT_SLOPE_WALL[None], False, evidence, moves, DOWN, MU)[0]
    # the wall's top is 0.234 m from the first contact: a shorter max_slide cuts the slide
    # before it separates, and the first contact is all it shows
    for max_slide in (0.2, 0.05, 0.0):
        cut = _slide(BENT_SLOPE_WALL, BENT_LOAD_MOVE, slide_on_slip=True, max_slide=max_slide)
        assert not cut.docked and not cut.separated and cut.stop_feature == Feature("edge", 0)
        assert np.array_equal(cut.observations.a, rigid.observations.a)
    assert _slide(BENT_SLOPE_WALL, BENT_LOAD_MOVE, slide_on_slip=True, max_slide=0.24).separated
    with pytest.raises(ValueError, match="max_slide"):
        _slide(BENT_SLOPE_WALL, BENT_LOAD_MOVE, slide_on_slip=True, max_slide=np.inf)


def test_a_non_compliant_slide_into_a_vertex_trap_does_not_dock_as_the_planner_predicts():
    path = [[0.6, 2.0], [0.6, 0.0]]  # NOTCH: a compliant slide is trapped at vertex 2
    run = _slide(NOTCH, path, slide_on_slip=True, max_slide=1.0)
    assert not run.docked and not run.separated and run.stop_feature == Feature("vertex", 2)
    assert _run(NOTCH, path).docked  # compliant: the same slide docks there
    # the planner's non-compliant estimate (eq. 19) is of the same event
    assert not simulate.dock_outcomes(NOTCH, False, path, MU, DOWN, compliant=False)[0]
    floor = _slide(FLAT, [[0.2, 1.0], [0.2, -1.0]], slide_on_slip=True)
    assert floor.docked and not floor.separated  # a first contact that sticks still docks


def test_prefix_collision_and_no_contact():
    ex = _run(FLAT, [[0.5, 1.0], [0.5, -0.5], [0.0, -0.5], [0.0, -1.0]])
    assert ex.contact and not ex.docked
    assert ex.observations.status.tolist() == [Status.FREE, Status.COLLIDE]
    miss = _run(FLAT, [[0.0, 1.0], [0.5, 1.0], [0.5, 0.5]])
    assert not miss.contact and not miss.docked and miss.stop_feature is None
    assert miss.observations.status.tolist() == [Status.FREE, Status.FREE]
    assert np.allclose(miss.stop_point, [0.5, 0.5])
    # A move that crosses an edge from behind (from inside the solid) is not a contact.
    behind = _run(FLAT, [[0.0, -1.0], [0.0, 1.0]])
    assert not behind.contact


def test_bad_input():
    with pytest.raises(ValueError):
        _run(FLAT, [[0.0, 1.0]])
    with pytest.raises(ValueError):
        _run(FLAT, [[0.0, 1.0], [np.nan, 0.0]])
    with pytest.raises(ValueError):
        _run(np.array([[0.0, 0.0], [np.inf, 1.0]]), [[0.0, 1.0], [0.0, -1.0]])
    with pytest.raises(ValueError):
        _run(FLAT, [[0.0, 1.0], [0.0, -1.0]], load=[0.0, 0.0])
    # A zero-length loading move touches nothing.
    assert not _run(FLAT, [[0.0, 1.0], [0.0, 1.0]]).contact


def _crosses(a, b, vertices):
    c, d = vertices[:-1], vertices[1:]
    den = cross(d - c, b - a)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross(d - c, c - a) / den
        t = cross(b - a, c - a) / den
    return bool(np.any((den != 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=8),
    st.floats(-0.8, 0.8),
    st.floats(-0.6, 0.6),
)
def test_observations_are_consistent_with_truth(heights, x, tilt):
    xs = np.linspace(1.0, -1.0, len(heights))
    truth = np.stack([xs, heights], axis=1)
    load = np.array([np.sin(tilt), -np.cos(tilt)])
    start = np.array([x, 1.0])
    ex = _run(truth, [start, start + 2.5 * load], load=load)
    obs = ex.observations
    for a, b, s in zip(obs.a, obs.b, obs.status, strict=True):
        if s == Status.FREE and np.linalg.norm(b - a) > 0:
            assert not _crosses(a, b, truth)
        elif s != Status.FREE:
            assert _crosses(a, b, truth)
    assert ex.contact == bool(np.any(obs.is_contact))


def test_monte_carlo_matches_hand_count():
    rng = np.random.default_rng(3)
    # Slopes of random angle: docks on the flat edge iff the angle is within atan(mu).
    angles = rng.uniform(-0.9, 0.9, 400)
    samples = np.stack(
        [
            np.stack([np.cos(angles), np.sin(angles)], 1),
            -np.stack([np.cos(angles), np.sin(angles)], 1),
        ],
        axis=1,
    )
    path = [[0.0, 2.0], [0.0, -2.0]]
    p = simulate.monte_carlo_dock_probability(samples, False, path, MU, DOWN, compliant=False)
    assert p == pytest.approx(np.mean(np.abs(angles) <= np.arctan(MU)))
    with pytest.raises(ValueError):
        simulate.monte_carlo_dock_probability(samples[:0], False, path, MU, DOWN)


def test_feasible():
    sloper = problems.get("sloper")
    mean = sloper.prior.mean_vertices
    assert simulate.feasible(sloper, mean) in (True, False)
    steep = mean.copy()
    flatter = mean.copy()
    # rotate the shape about its centre to make the top slope steeper / flatter than atan(mu)
    for out, ang in ((steep, -0.15), (flatter, 0.15)):  # CCW flattens it
        centre = mean.mean(axis=0)
        rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        out[:] = (mean - centre) @ rot.T + centre
    assert not simulate.feasible(sloper, steep)
    assert simulate.feasible(sloper, flatter)
    assert simulate.feasible(sloper, FLAT)
    assert simulate.feasible(sloper, CORNER)
    assert not simulate.feasible(sloper, SLOPE_CLIFF[:3])


def _cave(roof_y: float) -> np.ndarray:
    """A 45 degree slope (too steep) over a cave whose flat floor (y = 0, x in [0, 0.5]) lies
    under a roof at ``roof_y``, then a 45 degree slope down: no straight move from above
    touches the floor; a tool gets to it round the overhang's tip at x = 0."""
    return np.array(
        [[1.0, 1.5], [0.0, 0.5], [0.0, roof_y], [0.5, roof_y], [0.5, 0.0], [0.0, 0.0], [-1.0, -1.0]]
    )


@pytest.mark.parametrize("compliant", [True, False])
def test_a_floor_under_an_overhang_is_a_docking_site(compliant):
    sloper = problems.get("sloper")  # mu = 0.5, load straight down
    cave = _cave(0.4)
    assert simulate.feasible(sloper, cave, compliant)
    assert simulate.holding_margin(sloper, cave, compliant) == pytest.approx(-ALPHA, abs=1e-9)
    # the simulator agrees: in under the tip, then down onto the floor, it docks
    ex = _run(cave, [[-0.3, 0.2], [0.25, 0.2], [0.25, -0.1]], compliant)
    assert ex.docked and ex.stop_feature == Feature("edge", 4)
    assert np.allclose(ex.stop_point, [0.25, 0.0])
    # a gap narrower than the loading moves' start (NEAR_START_M): no free start, no site
    slit = _cave(0.5 * simulate.NEAR_START_M)
    assert not simulate.feasible(sloper, slit, compliant)
    assert simulate.holding_margin(sloper, slit, compliant) > 0


def test_feasible_without_compliance_needs_a_first_contact_that_sticks():
    sloper = problems.get("sloper")
    # CORNER docks only by sliding into its corner; FLAT sticks where it is touched
    assert simulate.feasible(sloper, CORNER) and simulate.feasible(sloper, NOTCH)
    assert not simulate.feasible(sloper, CORNER, compliant=False)
    assert not simulate.feasible(sloper, NOTCH, compliant=False)
    assert simulate.feasible(sloper, FLAT, compliant=False)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=4, max_size=4))
def test_plane_vector_helpers(values):
    u, v = np.array(values[:2]), np.array(values[2:])
    assert cross(u, v) == pytest.approx(perp(u) @ v, abs=1e-9)
    np.testing.assert_array_equal(outward_normal(u), -perp(u))  # right of travel
    assert cross(u, perp(u)) == pytest.approx(u @ u, abs=1e-9)  # perp turns counter-clockwise
    np.testing.assert_array_equal(cross(np.stack([u, v]), v), [cross(u, v), cross(v, v)])


ALPHA = np.degrees(np.arctan(MU))  # 26.57 degrees: the friction cone's half angle


def _slope(degrees):
    """One edge falling to the right at ``degrees`` (right to left: solid below)."""
    s = np.tan(np.deg2rad(degrees))
    return np.array([[1.0, -s], [-1.0, s]])


@pytest.mark.parametrize("compliant", [True, False])
def test_holding_margin_of_a_floor_and_of_slopes(compliant):
    sloper = problems.get("sloper")  # mu = 0.5, load straight down
    # flat floor, vertical load: the load sits on the cone's axis, atan(mu) to spare
    margin = simulate.holding_margin(sloper, FLAT, compliant)
    assert margin == pytest.approx(-ALPHA, abs=1e-9)
    # slopes: holds by alpha - slope, or is that many degrees too steep (a slide falls off)
    for degrees in (10.0, ALPHA - 0.3, ALPHA + 0.3, ALPHA + 5.0, 60.0):
        margin = simulate.holding_margin(sloper, _slope(degrees), compliant)
        assert margin == pytest.approx(degrees - ALPHA, abs=1e-9)
    # a load tilted by beta from the floor's normal: beta - alpha
    tilted = dataclasses.replace(sloper, load=np.array([np.sin(0.6), -np.cos(0.6)]))
    margin = simulate.holding_margin(tilted, FLAT, compliant)
    assert margin == pytest.approx(np.degrees(0.6) - ALPHA, abs=1e-9)
    assert simulate.holding_margin(sloper, FLAT[::-1], compliant) == np.inf  # faces away


def test_holding_margin_of_a_vertex_trap():
    """A V of two 60 degree walls: each wall alone is 60 - alpha too steep, and a slide down
    either wall is trapped at the bottom until the load tilts 30 degrees, where the other wall
    stops facing it (the simulator separates there)."""
    sloper = problems.get("sloper")
    v = np.array([[1.0, np.sqrt(3.0)], [0.0, 0.0], [-1.0, np.sqrt(3.0)]])
    assert simulate.holding_margin(sloper, v, compliant=True) == pytest.approx(-30.0)
    assert simulate.holding_margin(sloper, v, compliant=False) == pytest.approx(60.0 - ALPHA)
    # A 45 degree slope slides on into a pocket under a 45 degree roof: the pocket's floor is
    # 3 degrees too steep, whether the slide reaches it or a path round the roof's edge (no
    # straight move from above touches it); the pocket's back wall overhangs by 13 degrees, so
    # the slide separates there.
    s = np.tan(np.deg2rad(ALPHA + 3.0))
    pocket = np.array([[1, 1], [0, 0], [-0.5, -0.5 * s], [-0.2, 1.0], [0.3, 1.2], [-1.0, 2.5]])
    assert simulate.holding_margin(sloper, pocket) == pytest.approx(3.0)
    assert simulate.holding_margin(sloper, pocket, compliant=False) == pytest.approx(3.0)
    # CORNER's trap: the wall slid onto faces the load up to 90 degrees
    assert (
        simulate.holding_margin(sloper, CORNER)
        < 0
        < simulate.holding_margin(sloper, CORNER, compliant=False)
    )


@pytest.mark.parametrize("name", problems.names())
@pytest.mark.parametrize("compliant", [True, False])
def test_holding_margin_is_negative_exactly_on_feasible_truths(name, compliant):
    problem = problems.get(name)
    margins, feasible = [], []
    for seed in range(40):
        truth = problem.sample_ground_truth(np.random.default_rng([12, seed]))
        margins.append(simulate.holding_margin(problem, truth, compliant))
        feasible.append(simulate.feasible(problem, truth, compliant))
    margins = np.array(margins)
    np.testing.assert_array_equal(margins < 0, feasible)
    assert np.all(np.isfinite(margins)) and np.all(margins != 0)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=8),
    st.floats(-0.6, 0.6),
    st.booleans(),
)
def test_holding_margin_sign_matches_feasible_on_random_profiles(heights, tilt, compliant):
    sloper = problems.get("sloper")
    problem = dataclasses.replace(sloper, load=np.array([np.sin(tilt), -np.cos(tilt)]))
    truth = np.stack([np.linspace(1.0, -1.0, len(heights)), heights], axis=1)
    margin = simulate.holding_margin(problem, truth, compliant)
    assert (margin < 0) == simulate.feasible(problem, truth, compliant)
