"""Docking planner (Sec. V-B) on prior samples of the benchmark problems."""

import dataclasses
import re

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core import planner, problems, probsim, simulate
from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.freespace import FreeSpace, likely_obstacle_region
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.core.shape import GaussianShape


def _prior_plan(name, seed=0, count=60, start=None, targets=(), **settings):
    problem = problems.get(name)
    rng = np.random.default_rng(seed)
    samples = problem.prior.vertices(problem.prior.sample_z(rng, count))
    state = EpisodeState(targets=targets, tool=problem.start if start is None else start)
    config = PlannerConfig(problem.load, problem.contact_resolution, **settings)
    return problem, samples, planner.plan(samples, problem.prior, state, config)


@pytest.mark.parametrize("name", problems.names())
def test_plan_is_free_then_loads_through_target_edge(name):
    problem, samples, plan = _prior_plan(name)
    assert plan.decision == "dock", plan.reason
    mean = samples.mean(axis=0)
    outline = shapely.LineString(mean)
    assert np.allclose(plan.path[0], problem.start)
    assert not shapely.intersects(outline, shapely.LineString(plan.path[:-1]))
    a, b = plan.path[-2], plan.path[-1]
    direction = (b - a) / np.linalg.norm(b - a)
    assert np.allclose(direction, problem.load, atol=1e-9)
    c, d = mean[problem.prior.edges[plan.target_edge]]
    assert np.allclose(plan.target_point, 0.5 * (c + d))
    assert shapely.intersects(shapely.LineString([a, b]), shapely.LineString([c, d]))
    posterior = GaussianShape.from_samples(samples, problem.prior.closed, problem.friction)
    whole = probsim.dock_probability(posterior, plan.path, problem.load)
    holding = planner.holding_frequencies(samples, False, problem.load, problem.friction)
    expected = planner.capped_p_dock(whole.p_stop_vertex_sides, whole.p_stop_edge, holding)
    assert plan.p_dock == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert plan.p_dock <= whole.p_dock + 1e-12  # the cap only removes probability
    assert plan.p_dock >= plan.candidates.p_dock.max() * 0.5  # prefix rarely touches anything


def test_objective_applies_exploration_bonus():
    _, _, first = _prior_plan("three_ledges")
    _, _, again = _prior_plan("three_ledges", targets=[first.target_point])
    assert again.target_point.tolist() != first.target_point.tolist()
    bonus = planner.exploration_bonus(first.candidates.aim, [first.target_point], 0.01)
    j = np.flatnonzero(first.candidates.edges == first.target_edge)[0]
    assert bonus[j] == 0.0 and np.all(bonus >= 0) and np.all(bonus <= 1)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 8))
def test_lor_covers_every_sample_edge(seed, count):
    shape = problems.get("notch").prior
    samples = shape.vertices(shape.sample_z(np.random.default_rng(seed), count))
    lor = likely_obstacle_region(samples, shape.edges, margin=1e-4)
    for s in samples:
        assert shapely.covers(lor, shapely.LineString(s))


def test_shortest_path_avoids_obstacles_and_is_no_longer_than_detour():
    block = shapely.box(-1.0, -1.0, 1.0, 1.0)
    start, goal = np.array([-2.0, 0.0]), np.array([1.05, 0.0])
    space = FreeSpace(block, np.array([[1.0, 1.0], [-1.0, 1.0]]), False, start)
    path = space.shortest_path(start, goal)
    assert path is not None and len(path) >= 3
    assert not shapely.intersects(shapely.LineString(path), shapely.box(-0.99, -0.99, 0.99, 0.99))
    length = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    assert length <= np.hypot(1.0, 1.0) + 2 + np.hypot(0.05, 1.0) + 0.02  # over the top


def test_paths_cannot_go_round_an_open_profiles_ends_into_the_rock():
    """A hill seen from above, ending on its two flanks (solid below, walked right to left):
    the rock under it is an obstacle, so the way to a point under the hill is blocked, while
    beside it, above the extended flanks, the space stays free."""
    hill = np.array([[0.4, -0.4], [0.2, 0.0], [0.0, 0.1], [-0.2, 0.0], [-0.4, -0.4]])
    lor = shapely.buffer(shapely.LineString(hill), 0.005)
    start = np.array([0.0, 0.5])
    space = FreeSpace(lor, hill, False, start)
    under = [[0.0, -0.6], [0.5, -0.9], [-0.5, -0.9]]  # below the chord of the two ends too
    assert space.blocked(np.array(under)).all()
    assert space.shortest_path(start, np.array([0.0, -0.6])) is None
    assert not space.blocked(np.array([[0.6, -0.4], [-0.6, -0.4]])).any()
    path = space.shortest_path(start, np.array([0.6, -0.4]))
    assert path is not None and not shapely.intersects(shapely.LineString(path), space.obstacles)


def test_a_tool_on_the_outline_leaves_the_way_it_came():
    """On the mean outline ``ascend`` has no direction; ``retrace`` walks the tool's own free
    moves back out of the likely-obstacle region, from the end of the last free move (the core
    loop) or from a point the executor retreated to along it."""
    block = shapely.box(-1.0, -1.0, 1.0, 1.0)
    outline = np.array([[1.0, 1.0], [-1.0, 1.0]])
    space = FreeSpace(block, outline, False, np.array([0.0, 1.0]))
    assert space.ascend(np.array([0.0, 1.0]), 0.05) is None  # on the outline
    history = History(
        [[3.0, 3.0], [0.0, 2.0], [0.0, 1.5], [0.5, 0.98], [0.0, 0.97]],
        [[3.0, 2.5], [0.0, 1.5], [0.0, 0.97], [0.5, 0.9], [0.0, 0.95]],
        [Status.FREE, Status.FREE, Status.FREE, Status.FREE, Status.COLLIDE],
    )
    for start in ([0.0, 0.97], [0.0, 0.99], [0.003, 0.985], [0.02, 0.96]):  # the last: retreated
        path = planner.retrace(history, np.array(start), space, 0.005, 0.35)
        np.testing.assert_allclose(path[[0, -1]], [start, [0.0, 1.5]])
        assert len(path) <= 3 and np.allclose(path[1:, 0], 0.0)  # then along move 3
    deep = History([[0.0, 2.0], [0.0, 0.9]], [[0.0, 0.9], [0.0, 0.5]], [Status.FREE] * 2)
    path = planner.retrace(deep, np.array([0.0, 0.5]), space, 0.005, 0.35)  # (0, 0.9) is blocked
    np.testing.assert_allclose(path, [[0.0, 0.5], [0.0, 0.9], [0.0, 2.0]])
    assert planner.retrace(History(), np.array([0.0, 0.97]), space, 0.005, 0.35) is None
    assert (
        planner.retrace(history, np.array([-0.5, 0.9]), space, 0.005, 0.35) is None
    )  # off every move
    assert planner.retrace(history, np.array([0.3, 0.5]), space, 0.005, 0.35) is None  # too far


@pytest.mark.parametrize("max_slide", [0.3, 0.6])
def test_a_tool_a_slide_away_from_its_moves_steps_straight_back_to_them(max_slide):
    """A non-compliant slide run for evidence that stuck reports only its first contact: the
    executor leaves the tool up to its ``max_slide`` plus its retreat from every recorded
    move. The planner, told that ``max_slide`` (``PlannerConfig``), steps straight back to the
    latest move and follows it out; farther than that reach, no move is the tool's."""
    block = shapely.box(-1.0, -1.0, 1.0, 1.0)
    space = FreeSpace(block, np.array([[1.0, 1.0], [-1.0, 1.0]]), False, np.array([0.0, 2.0]))
    history = History(
        [[0.0, 2.0], [0.0, 0.995]], [[0.0, 0.995], [0.0, 0.985]], [Status.FREE, Status.SLIP_LEFT]
    )
    # the slip row dropped by the sampler: the tool leaves the way it came first (``_lead``)
    state = dataclasses.replace(EpisodeState().record(history, 1), dropped=np.array([1]))
    assert planner.RETRACE_MARGIN >= 0.02 + 0.02  # the retreat and the release
    for slide in (0.05, max_slide - 0.01):
        slid = np.array([-slide - 0.02, 0.99])  # slid left along the face, then retreated
        path = planner._lead(space, slid, state, 0.005, max_slide)
        np.testing.assert_allclose(path, [slid, [0.0, 0.995], [0.0, 2.0]])  # its nearest point
    beyond = np.array([-max_slide - planner.RETRACE_MARGIN - 0.01, 0.99])
    assert (
        planner.retrace(history, beyond, space, 0.005, max_slide + planner.RETRACE_MARGIN) is None
    )


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "0.3", None])
def test_a_bad_max_slide_is_refused(bad):
    with pytest.raises(ValueError, match="max_slide"):
        PlannerConfig(max_slide=bad)


def test_retrace_crosses_from_a_plan_to_the_move_the_executor_retreated_along():
    """A plan starts where the executor's retreat (not recorded) left the tool: 1 cm back along
    the previous plan's last move, not at its end. The walk continues along that move."""
    block = shapely.box(-1.0, -1.0, 1.0, 1.0)
    space = FreeSpace(block, np.array([[1.0, 1.0], [-1.0, 1.0]]), False, np.array([0.0, 2.0]))
    history = History(
        [[0.0, 2.0], [0.0, 0.965], [0.0, 0.98], [0.505, 0.975]],
        [[0.0, 0.97], [0.0, 0.955], [0.5, 0.98], [0.515, 0.985]],  # plan 1: down, collided
        [Status.FREE, Status.COLLIDE, Status.FREE, Status.COLLIDE],  # plan 2: from its retreat
    )
    start = np.array([0.49, 0.98])  # retreated along plan 2's move
    path = planner.retrace(history, start, space, 0.005, 0.35)
    np.testing.assert_allclose(path, [start, [0.0, 0.98], [0.0, 2.0]])
    assert not space.blocked(path[-1])[0]
    cut = History(history.a[2:], history.b[2:], history.status[2:])  # without plan 1's move
    assert planner.retrace(cut, start, space, 0.005, 0.35) is None


@pytest.mark.parametrize("name", problems.names())
def test_holding_frequencies_match_the_simulated_contacts(name):
    problem, samples, _ = _prior_plan(name)
    q_edge, q_vertex = planner.holding_frequencies(samples, False, problem.load, problem.friction)
    edges = problem.prior.edges
    for e in range(len(edges)):  # a handful of dozen edges, each one vectorized call
        which = np.full(len(samples), e)
        rigid = simulate.slide_outcomes(
            samples, False, which, problem.load, problem.friction, False
        )
        facing = samples[:, edges[e, 1]] - samples[:, edges[e, 0]]
        faces = facing @ simulate.friction_functionals(problem.load, problem.friction)[2] > 0
        assert q_edge[e] == pytest.approx(np.mean((rigid[0] == simulate.STUCK_EDGE) & faces))
        # a compliant slide from edge e that ends stuck at a vertex: that vertex can trap
        outcome, vertex, _ = simulate.slide_outcomes(
            samples, False, which, problem.load, problem.friction, True
        )
        stuck = outcome == simulate.STUCK_VERTEX
        for v in np.unique(vertex[stuck]):
            side = 0 if v <= e else 1  # arrived by a left slide (toward lower indices) or right
            assert q_vertex[side, v] >= np.mean(stuck & (vertex == v)) - 1e-12
    assert np.all((q_edge >= 0) & (q_edge <= 1)) and np.all(q_vertex[:, [0, -1]] == 0.0)


def test_cap_removes_features_no_sample_lets_hold():
    stop_vertex = np.array([[[0.1, 0.2, 0.0], [0.0, 0.03, 0.0]]])  # (1 move, 2 arrivals, 3)
    stop_edge = np.array([[0.3, 0.05]])
    holding = (np.array([0.0, 0.5]), np.array([[0.0, 0.01, 0.0], [0.0, 0.5, 0.0]]))
    capped = planner.capped_p_dock(stop_vertex, stop_edge, holding)
    assert capped == pytest.approx([0.05 + 0.01 + 0.03])
    # a vertex that traps only slides from its other side: a left slide's stop there counts 0
    one_sided = (holding[0], np.array([[0.0, 0.0, 0.0], [0.0, 0.5, 0.0]]))
    assert planner.capped_p_dock(stop_vertex, stop_edge, one_sided) == pytest.approx([0.08])


@pytest.mark.parametrize("compliant", [True, False])
def test_a_path_that_docks_on_no_sample_scores_zero(compliant):
    """Half the samples hold on a flat edge the move stops short of, half put a steep edge in
    its way: the feature cap keeps the Gaussian fit's ~5 %, the samples (eq. 19) say 0."""
    rng = np.random.default_rng(0)
    low, steep = np.array([[0.1, -0.2], [-0.1, -0.2]]), np.array([[0.1, 0.1], [-0.1, -0.1]])
    samples = np.concatenate([np.repeat(low[None], 20, 0), np.repeat(steep[None], 20, 0)])
    samples += 0.005 * rng.standard_normal(samples.shape)
    load = np.array([0.0, -1.0])
    posterior = GaussianShape.from_samples(samples, False, 0.5)
    holding = planner.holding_frequencies(samples, False, load, 0.5)
    short, through = np.array([[0.0, 0.3], [0.0, -0.1]]), np.array([[0.0, 0.3], [0.0, -0.3]])
    estimate = probsim.dock_probability(posterior, short, load, compliant)
    capped = planner.capped_p_dock(estimate.p_stop_vertex_sides, estimate.p_stop_edge, holding)
    assert holding[0][0] == 0.5 and capped > 0.01
    assert planner.whole_path_p_dock(posterior, samples, short, load, compliant, holding) == 0.0
    reaching = planner.whole_path_p_dock(posterior, samples, through, load, compliant, holding)
    assert 0.3 < reaching <= 0.5


def test_no_edge_facing_the_load_gives_up():
    # a flat floor (solid below, vertices right to left) pulled upward: no edge resists the load
    xs = np.linspace(0.3, -0.3, 6)
    mean = np.stack([xs, np.zeros(6)], axis=1).ravel()
    basis = np.tile([[0.0, 0.0], [0.0, 0.01]], (6, 1))[:, 1:]  # vertical offset, 1 cm
    shape = GaussianShape(mean, basis, closed=False, friction=0.5)
    samples = shape.vertices(shape.sample_z(np.random.default_rng(0), 20))
    plan = planner.plan(samples, shape, EpisodeState(tool=[0.0, 0.3]), PlannerConfig((0.0, 1.0)))
    assert plan.decision == "give_up" and "faces" in plan.reason
    assert plan.path.shape == (0, 2) and plan.target_edge == -1


def test_closure_edges_are_never_docking_sites():
    """A flat tail past the slice's end (perception's closure edge) looks like a sure hold;
    marked as a closure edge it holds nothing, and neither do the vertices on it."""
    mean = np.array([[0.3, -0.6], [0.3, -0.3], [0.15, -0.15], [0.0, 0.0], [-0.3, 0.0]]).ravel()
    basis = 0.003 * np.random.default_rng(1).standard_normal((10, 4))
    load = (0.0, -1.0)
    for closure, decision in (((), "dock"), ((0, 3), "give_up")):
        shape = GaussianShape(mean, basis, closed=False, friction=0.5, closure_edges=closure)
        samples = shape.vertices(shape.sample_z(np.random.default_rng(0), 40))
        q_edge, q_vertex = planner.holding_frequencies(samples, False, load, 0.5, closure)
        plan = planner.plan(samples, shape, EpisodeState(tool=[0.0, 0.4]), PlannerConfig(load))
        assert plan.decision == decision, plan.reason
        if closure:
            assert q_edge[3] == 0.0 and np.all(q_vertex[:, [0, 1, 3, 4]] == 0.0)
            assert "threshold" in plan.reason
        else:
            assert q_edge[3] > 0.9 and plan.target_edge == 3


def test_start_inside_lor_climbs_out_or_gives_up_with_reason():
    """A tool 3 mm off the mean surface (inside the likely-obstacle region) near three edges:
    each plan either gives up with a reason or climbs out from the tool without crossing the
    mean outline, and some climb out."""
    problem, samples, _ = _prior_plan("three_ledges")
    mean = samples.mean(axis=0)
    docked = 0
    for edge in (5, 30, 60):
        c, d = mean[problem.prior.edges[edge]]
        normal = np.array([d[1] - c[1], c[0] - d[0]]) / np.linalg.norm(d - c)  # outward
        start = 0.5 * (c + d) + 0.003 * normal
        _, _, plan = _prior_plan("three_ledges", start=start)
        assert plan.reason
        if plan.decision == "dock":
            docked += 1
            assert np.allclose(plan.path[0], start)
            outline = shapely.LineString(mean)
            assert not shapely.intersects(outline, shapely.LineString(plan.path[:-1]))
    assert docked > 0


def test_low_threshold_gap_gives_up():
    _, _, plan = _prior_plan("sloper", give_up_threshold=0.999)
    assert plan.decision == "give_up" and "threshold" in plan.reason


def test_bad_samples_or_an_unknown_tool_raise():
    problem = problems.get("sloper")
    samples = problem.prior.vertices(problem.prior.sample_z(np.random.default_rng(0), 5))
    state, config = EpisodeState(tool=problem.start), PlannerConfig(problem.load)
    with pytest.raises(ValueError, match="tool position is unknown"):
        planner.plan(samples, problem.prior, EpisodeState(), config)
    samples[2, 3, 0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        planner.plan(samples, problem.prior, state, config)
    with pytest.raises(ValueError, match="N >= 2"):
        planner.plan(samples[:1], problem.prior, state, config)


def test_sites_whose_whole_path_is_unlikely_to_dock_are_passed_over(monkeypatch):
    """The threshold applies to the whole path: when the way to every site likely touches
    something first (here: probsim says so), the planner gives up, except for IG's probes."""
    _, _, plan = _prior_plan("notch")
    assert plan.decision == "dock" and plan.p_dock >= 1e-3
    real = probsim.dock_probability

    def blocked_prefix(shape, path, load, compliant=True, method="sequential"):
        est = real(shape, path, load, compliant, method)
        scale = 1e-4 / max(est.p_dock, 1e-300)  # the prefix's no-contact probability, shrunk
        return probsim.DockEstimate(
            est.p_dock * scale, est.p_stop_vertex_sides * scale, est.p_stop_edge * scale, scale
        )

    monkeypatch.setattr(probsim, "dock_probability", blocked_prefix)
    for objective in ("ours", "greedy", "window"):
        _, _, plan = _prior_plan("notch", objective=objective)
        assert plan.decision == "give_up", objective
        worst = re.search(r"whole path ([0-9.e+-]+) < threshold 0.001", plan.reason)
        assert worst and 0 < float(worst.group(1)) <= 1e-4, plan.reason
    _, _, probe = _prior_plan("notch", objective="info_gain")
    assert probe.decision == "dock" and probe.p_dock < 1e-3


def test_a_tool_whose_latest_evidence_was_dropped_leaves_the_way_it_came():
    """The sampler dropped the latest move's contact: the estimate contradicts where the tool
    is, so the plan first walks back along that move's free part, though the tool is free."""
    problem = problems.get("notch")
    samples = problem.prior.vertices(problem.prior.sample_z(np.random.default_rng(0), 60))
    tool = np.array([0.0, 0.3])
    history = History(
        [[0.0, 0.45], [0.0, 0.305]], [[0.0, 0.305], [0.0, 0.295]], [Status.FREE, Status.COLLIDE]
    )
    config = PlannerConfig(problem.load, problem.contact_resolution)
    kept = EpisodeState(history=history, move_ids=[1, 1], tool=tool)
    lost = EpisodeState(history=history, move_ids=[1, 1], dropped=[1], tool=tool)
    plans = [planner.plan(samples, problem.prior, s, config) for s in (kept, lost)]
    assert [p.decision for p in plans] == ["dock", "dock"]
    np.testing.assert_allclose(plans[1].path[:3], [tool, [0.0, 0.305], [0.0, 0.45]])
    assert not np.allclose(plans[0].path[1], [0.0, 0.305])  # from a trusted place: straight on
    unknown = EpisodeState(history=history, move_ids=[0, 0], dropped=[1], tool=tool)
    unknown_plan = planner.plan(samples, problem.prior, unknown, config)  # no move to go back on
    np.testing.assert_allclose(unknown_plan.path, plans[0].path)


@pytest.mark.parametrize("name", problems.names())
def test_no_path_leaves_the_workspace_box(name):
    problem, _, free = _prior_plan(name)
    lo, hi = free.path.min(axis=0), free.path.max(axis=0)
    _, _, same = _prior_plan(name, workspace=(lo, hi))  # a box around the free plan's path
    assert same.decision == "dock" and np.array_equal(same.path, free.path)
    end = free.path[-1]  # a box without the free plan's end: another path inside, or a give-up
    box = (lo - 1.0, np.array([hi[0] + 1.0, hi[1] + 1.0]))
    box[0][1] = end[1] + 1e-6
    _, _, boxed = _prior_plan(name, workspace=box)
    if boxed.decision == "dock":
        assert np.all(boxed.path >= box[0]) and np.all(boxed.path <= box[1])
    else:
        assert "leave the workspace box" in boxed.reason, boxed.reason
    start = np.asarray(problem.start)  # a box around the start only: nothing to plan
    _, _, none = _prior_plan(name, workspace=(start - 1e-3, start + 1e-3))
    assert none.decision == "give_up" and "leave the workspace box" in none.reason


@pytest.mark.parametrize(
    "box", [((0.0, 0.0), (0.0, 1.0)), ((0.0, 0.0), (1.0,)), ((np.nan, 0.0), (1.0, 1.0))]
)
def test_a_bad_workspace_box_is_refused(box):
    with pytest.raises(ValueError, match="workspace"):
        PlannerConfig(workspace=box)


def _rarely_holding_prior_and_no_holding_samples():
    """Sloper's prior at friction 0.3 (an edge holds in ~0.3-0.7 % of draws) and 100 of its
    draws in which nothing holds."""
    prior = problems.get("sloper").prior
    shape = GaussianShape(prior.mean, prior.basis, prior.closed, 0.3, prior.closure_edges)
    load = problems.get("sloper").load
    for seed in range(100):
        samples = shape.vertices(shape.sample_z(np.random.default_rng(seed), 100))
        q_edge, q_vertex = planner.holding_frequencies(samples, False, load, 0.3)
        if q_edge.max() == 0 and q_vertex.max() == 0:
            return shape, samples
    raise AssertionError("no seed drew 100 samples without a hold")


def test_the_first_cycle_counts_prior_draws_before_giving_up(monkeypatch):
    """No hold in the 100 samples: the first cycle still docks, because the prior's own draws
    (up to 3 / threshold) show holds; with the draws cut to the samples it gives up."""
    problem = problems.get("sloper")
    shape, samples = _rarely_holding_prior_and_no_holding_samples()
    state = EpisodeState(tool=problem.start)
    config = PlannerConfig(problem.load, problem.contact_resolution)
    plan = planner.plan(samples, shape, state, config)
    assert plan.decision == "dock" and plan.p_dock >= config.give_up_threshold, plan.reason
    extra = planner.first_cycle_draws(shape, state, len(samples), config.give_up_threshold)
    holding = planner.holding_frequencies(
        np.concatenate([samples, extra]), False, problem.load, 0.3
    )
    assert 0 < holding[0].max() < 0.02  # rare, and only the prior draws show it
    assert plan.candidates.p_dock.max() <= holding[0].max() + holding[1].max() * 2
    monkeypatch.setattr(planner, "PRIOR_DRAWS_MAX", len(samples))
    cut = planner.plan(samples, shape, state, config)
    assert cut.decision == "give_up" and "best docking probability" in cut.reason


def test_prior_draws_only_before_any_observation_and_up_to_the_rule_of_three():
    problem = problems.get("sloper")
    shape, samples = problem.prior, _prior_plan("sloper", count=100)[1]
    empty = EpisodeState(tool=problem.start)
    extra = planner.first_cycle_draws(shape, empty, 100, 1e-3)
    assert extra.shape == (2900, *samples.shape[1:])
    assert np.array_equal(extra, planner.first_cycle_draws(shape, empty, 100, 1e-3))  # seeded
    assert len(planner.first_cycle_draws(shape, empty, 100, 0.0)) == planner.PRIOR_DRAWS_MAX - 100
    assert len(planner.first_cycle_draws(shape, empty, 100, 1e-2)) == 200
    assert len(planner.first_cycle_draws(shape, empty, 100, 0.05)) == 0  # 60 < 100
    seen = EpisodeState().record(History([[0.0, 2.0]], [[0.0, 1.5]], [Status.FREE]), 1)
    assert len(planner.first_cycle_draws(shape, seen, 100, 1e-3)) == 0
    draws = [planner.give_up_draws(t) for t in (1e-3, 1e-2, 0.05, 7e-3, 1e-4, 0.0)]
    assert draws == [3000, 300, 60, 429, planner.PRIOR_DRAWS_MAX, planner.PRIOR_DRAWS_MAX]


def test_a_plan_above_the_threshold_uses_only_its_samples(monkeypatch):
    """The prior draws are for would-be give-ups only: a first plan that docks on its samples
    is the same without them."""
    plan = _prior_plan("three_ledges", count=100)[2]
    monkeypatch.setattr(planner, "PRIOR_DRAWS_MAX", 0)
    _, _, alone = _prior_plan("three_ledges", count=100)
    assert plan.decision == alone.decision == "dock"
    assert plan.p_dock == alone.p_dock and np.array_equal(plan.path, alone.path)
