"""A compliant slide as evidence (core.slides): the truth passes, a hold on the way fails."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core import explore, planner, problems, simulate, slides
from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.core.shape import GaussianShape

LOAD, MU, STEP = np.array([0.0, -1.0]), 0.5, 0.025


def slope_shape(n=7, degrees=40.0):
    """A straight slope falling to the right (+x), steeper than the friction angle (26.6 deg),
    numbered right to left (solid below it): a slide down it runs to lower edge indices."""
    x = -np.arange(n) * STEP
    return np.stack([x, -np.tan(np.radians(degrees)) * x], axis=1)


def slide_probes(vertices, edges):
    """Long vertical slip-left (down the slope) observations through the middles of ``edges``,
    in this order."""
    mid = 0.5 * (vertices[edges] + vertices[np.asarray(edges) + 1])
    up = np.array([0.0, 0.05])
    return History(mid + up, mid - up, np.full(len(mid), Status.SLIP_LEFT))


def level_edge(vertices, edge):
    """The slope with ``edge`` made level (it then holds the load); later vertices move down."""
    out = vertices.copy()
    out[edge + 1 :, 1] += vertices[edge, 1] - vertices[edge + 1, 1]
    return out


def test_pieces_near_the_load_direction_give_no_slip_observation():
    """A segment along the load crosses a piece only within contact_resolution * sin / 2 of
    its middle: a piece closer than 30 degrees to the load (a wall below a ledge lip) gives no
    row, a 31-degree ledge piece does."""
    push = np.array([0.0, -1.0])
    starts = np.array([[0.0, 0.0], [0.1, -0.1], [0.3, -0.1]])
    ends = np.array([[0.1, -0.06], [0.102, -0.15], [0.32, -0.14]])  # 59, 2.3, 26.6 deg off load
    evidence = slides.crossed_piece_evidence(starts, ends, push, 0.005, Status.SLIP_LEFT, 1.0)
    np.testing.assert_allclose(0.5 * (evidence.a + evidence.b), [[0.05, -0.03]])
    np.testing.assert_allclose(evidence.b - evidence.a, [[0.0, -0.005]])
    assert evidence.status.tolist() == [Status.SLIP_LEFT]


def test_a_crossed_piece_gives_one_observation_per_evidence_spacing():
    push = np.array([0.0, -1.0])
    starts, ends = np.array([[0.0, 0.0], [0.1, 0.0]]), np.array([[0.05, 0.0], [0.11, 0.0]])
    evidence = slides.crossed_piece_evidence(starts, ends, push, 0.004, Status.SLIP_RIGHT, 0.02)
    middles = 0.5 * (evidence.a + evidence.b)
    np.testing.assert_allclose(middles[:, 0], [0.05 / 6, 0.025, 0.25 / 6, 0.105])  # 3 + 1 parts
    np.testing.assert_allclose(evidence.b - evidence.a, np.tile([0.0, -0.004], (4, 1)))
    assert evidence.status.tolist() == [Status.SLIP_RIGHT] * 4
    default = slides.crossed_piece_evidence(starts, ends, push, 0.004, Status.SLIP_RIGHT)
    assert len(default) == 2 + 1  # 5 cm and 1 cm at EVIDENCE_SPACING_M = 4 cm
    for bad in (0.0, -0.01, np.nan):
        with pytest.raises(ValueError, match="spacing"):
            slides.crossed_piece_evidence(starts, ends, push, 0.004, Status.SLIP_RIGHT, bad)


def test_a_level_edge_between_two_slide_observations_fails_the_sample():
    slope = slope_shape()
    history = slide_probes(slope, [3, 1])  # edge 2 in between carries no observation
    flat = level_edge(slope, 2)
    samples = np.stack([slope, flat])
    one_slide = slides.consistent_with_slides(samples, False, history, [7, 7], LOAD, MU)
    assert one_slide.tolist() == [True, False]
    # as two separate moves the observations say nothing about edge 2
    two_moves = slides.consistent_with_slides(samples, False, history, [7, 8], LOAD, MU)
    assert two_moves.tolist() == [True, True]
    unknown = slides.consistent_with_slides(samples, False, history, [0, 0], LOAD, MU)
    assert unknown.tolist() == [True, True]  # rows without a plan id form no slide


def test_rows_the_sampler_dropped_or_that_land_nowhere_do_not_judge_a_sample():
    slope = slope_shape()
    flat = level_edge(slope, 2)
    history = slide_probes(slope, [3, 1])
    samples = np.stack([slope, flat])
    dropped = slides.consistent_with_slides(samples, False, history, [7, 7], LOAD, MU, [1])
    assert dropped.tolist() == [True, True]  # one row left: no slide
    # a third row of the slide far off the surface: ignored, the other two still judge
    astray = history.extend([[1.0, 1.0]], [[1.0, 0.99]], [Status.SLIP_LEFT])
    ok = slides.consistent_with_slides(samples, False, astray, [7, 7, 7], LOAD, MU)
    assert ok.tolist() == [True, False]
    # a first contact that lands nowhere leaves the sample unjudged
    first_astray = History(astray.a[[2, 0, 1]], astray.b[[2, 0, 1]], astray.status[[2, 0, 1]])
    ok = slides.consistent_with_slides(samples, False, first_astray, [7, 7, 7], LOAD, MU)
    assert ok.tolist() == [True, True]


def test_a_slide_that_separated_rules_out_a_trap_after_its_last_row():
    slope = slope_shape()
    history = slide_probes(slope, [3, 2])  # the tool then slid on and fell off the end
    ends_level = level_edge(slope, 0)  # would trap it at vertex 1: it would have docked
    ends_steep = slope.copy()
    ends_steep[0] = slope[1] + [0.0, -STEP]  # a wall below vertex 1: it separates there
    overhang = slope.copy()
    overhang[0] = slope[1] + [-STEP, -STEP]  # turns back under the slope: separates
    samples = np.stack([slope, ends_level, ends_steep, overhang])
    ok = slides.consistent_with_slides(samples, False, history, [4, 4], LOAD, MU)
    assert ok.tolist() == [True, False, True, True]
    # a closed shape: the walk wraps past the first vertex to the trap
    closed = np.vstack([ends_level, [[slope[-1, 0], -1.0], [0.2, -1.0], [0.2, 0.0]]])
    for roll in range(len(closed)):
        rolled = np.roll(closed, roll, axis=0)
        ok = slides.consistent_with_slides(rolled[None], True, history, [4, 4], LOAD, MU)
        assert not ok[0], roll


def test_a_slide_that_runs_backwards_fails():
    slope = slope_shape()
    backwards = slide_probes(slope, [1, 3])  # the first contact below the later one
    ok = slides.consistent_with_slides(slope[None], False, backwards, [1, 1], LOAD, MU)
    assert not ok[0]


def test_a_closed_shape_checks_the_slide_across_its_first_vertex():
    slope = slope_shape()
    closed = np.vstack([slope, [[slope[-1, 0], -1.0], [0.0, -1.0]]])  # the solid under it
    history = slide_probes(slope, [3, 1])
    for roll in range(len(closed)):  # every numbering, including the span wrapping to index 0
        good = np.roll(closed, roll, axis=0)
        flat = np.roll(np.vstack([level_edge(slope, 2), closed[len(slope) :]]), roll, axis=0)
        ok = slides.consistent_with_slides(np.stack([good, flat]), True, history, [2, 2], LOAD, MU)
        assert ok.tolist() == [True, False], roll


def test_rows_without_a_slide_leave_every_sample():
    slope = slope_shape()
    history = slide_probes(slope, [3, 1]).extend([[0.0, 0.1]], [[0.0, 0.2]], [Status.FREE])
    flat = level_edge(slope, 2)
    ok = slides.consistent_with_slides(np.stack([slope, flat]), False, history, [1, 2, 3], LOAD, MU)
    assert ok.all()
    assert slides.slide_groups(history, [1, 2, 3]) == []


def test_dropped_rows_must_be_history_rows():
    history = slide_probes(slope_shape(), [3, 1])
    with pytest.raises(ValueError, match=r"dropped rows \[2\] outside the 2-row history"):
        slides.consistent_with_slides(slope_shape()[None], False, history, [1, 1], LOAD, MU, [2])


def test_move_ids_must_match_the_history():
    with pytest.raises(ValueError, match="move_ids has 1 entries for 2 history rows"):
        slides.consistent_with_slides(
            slope_shape()[None], False, slide_probes(slope_shape(), [1, 3]), [1], LOAD, MU
        )


@settings(max_examples=25, deadline=None)
@given(truth_seed=st.integers(0, 10_000), x=st.floats(-0.6, 0.3))
def test_the_truth_always_passes_its_own_slides(truth_seed, x):
    problem = problems.get("three_ledges")
    truth = problem.sample_ground_truth(np.random.default_rng(truth_seed))
    path = np.array([[x, 0.8], [x, -0.8]])
    run = simulate.guarded_path(truth, False, path, problem.friction, problem.load, True, 0.01)
    evidence = explore.slide_evidence(truth, False, run, problem.load, 0.01)
    ok = slides.consistent_with_slides(
        truth[None], False, evidence, np.ones(len(evidence)), problem.load, problem.friction
    )
    # A slide is evidence of a move that did not dock (a docked episode ends); one that ended
    # trapped at a vertex contradicts that, so the check must refuse it.
    trapped = run.docked and run.stop_feature is not None and run.stop_feature.kind == "vertex"
    assert ok[0] == (not (trapped and slides.slide_groups(evidence, np.ones(len(evidence)))))


def test_planner_drops_the_samples_a_slide_rules_out():
    slope = slope_shape()
    history = slide_probes(slope, [3, 1])
    flat = level_edge(slope, 2)
    up = np.array([0.0, 1e-3])
    samples = np.stack([slope, slope + up, slope - up, flat])
    prior = GaussianShape(slope.ravel(), 1e-3 * np.eye(slope.size), closed=False, friction=MU)
    blind, config = EpisodeState(history, tool=[0.05, 0.2]), PlannerConfig(LOAD, 0.01)
    plan = planner.plan(samples, prior, blind, config)  # moves unknown: no slide
    assert plan.rejected == 0 and plan.decision == "dock"  # the level edge holds in 1 of 4
    informed = blind.with_history(history, [3, 3])
    plan = planner.plan(samples, prior, informed, config)
    assert plan.rejected == 1 and plan.decision == "give_up", plan.reason
    plan = planner.plan(samples, prior, informed.sampled(dropped=[1]), config)
    assert plan.rejected == 0 and plan.decision == "dock"  # a dropped row takes no part
    pair = planner.plan(np.stack([slope, flat]), prior, informed, config)
    assert pair.rejected == 1 and pair.decision == "dock"  # fewer than two pass: all kept


def test_samples_are_checked_in_blocks_with_the_same_answer(monkeypatch):
    """The crossing test runs over blocks of samples (``CROSSING_BLOCK``); a block of one
    sample each gives every sample's answer as one block for all does."""
    slope = slope_shape(8, 35.0)
    rng = np.random.default_rng(4)
    samples = slope + rng.normal(0.0, 0.004, (60, *slope.shape))
    samples[::3] = level_edge(slope, 3)  # a level edge on the slide's way: fails
    history = slide_probes(slope, [5, 1])
    whole = slides.consistent_with_slides(samples, False, history, [4, 4], LOAD, MU)
    assert 0 < whole.sum() < len(whole) - 20  # both answers, the level-edge ones fail
    monkeypatch.setattr(slides, "CROSSING_BLOCK", 1)
    one_each = slides.consistent_with_slides(samples, False, history, [4, 4], LOAD, MU)
    np.testing.assert_array_equal(one_each, whole)
