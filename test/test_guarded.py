"""Guarded-move executor logic in closed loop with the mock physics (no DDS)."""

import copy
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core.history import Status
from tactile_dock_ros.execution.guarded import (
    ForceFilter,
    GuardedRun,
    Limits,
    Settings,
    move_seconds,
)
from tactile_dock_ros.execution.mock_physics import PointToolSim
from tactile_dock_ros.execution.types import Outcome, PlanCommand

FLOOR = np.array([[1.0, 0.0], [-1.0, 0.0]])  # y = 0, solid below (right to left)
SLOPE_DOWN_RIGHT = np.array([[1.0, -1.0], [-1.0, 1.0]])  # 45 degrees, too steep for mu = 0.5
SLOPE_DOWN_LEFT = np.array([[1.0, 1.0], [-1.0, -1.0]])
LIMITS = Limits(np.array([-0.9, -0.9]), np.array([0.9, 0.9]), 0.2, 40.0, 0.5)
DT = 0.01
SETTINGS = Settings()


def _plan(waypoints, speed=0.1, threshold=3.0, compliant=False):
    return PlanCommand(
        1, True, np.array(waypoints, float), np.array([0.0, -1.0]), threshold, speed, compliant,
        0.5, 0.5, 0, "",
    )  # fmt: skip


def _execute(
    terrain, waypoints, limits=LIMITS, settings=SETTINGS, speed=0.1, start=None,
    compliant=False, lateral_stiffness=None, forces=None,
):  # fmt: skip
    """Run the plan to its end; ``forces`` (a list) collects |force| at every tick."""
    start = waypoints[0] if start is None else start
    sim = PointToolSim(terrain, False, 0.5, 500.0, start, lateral_stiffness=lateral_stiffness)
    run = GuardedRun(_plan(waypoints, speed, compliant=compliant), sim.tool, limits, settings, 0.0)
    t, commanded = 0.0, []
    for _ in range(10_000):
        if run.done:
            break
        velocity = run.check_next(sim.tool, run.step(t, sim.tool, sim.force, 0.0), DT)
        commanded.append(velocity)
        if forces is not None:
            forces.append(float(np.linalg.norm(sim.force)))
        sim.step(velocity, DT)
        t += DT
    assert run.done
    return run, sim, np.array(commanded)


def test_docks_on_a_flat_floor_and_reports_free_then_stick():
    run, sim, _ = _execute(FLOOR, [[0.0, 0.3], [0.0, -0.1]])
    assert run.outcome is Outcome.DOCKED
    assert list(run.history.status) == [Status.FREE, Status.STICK]
    free_end, (a, b) = run.history.b[0], (run.history.a[1], run.history.b[1])
    assert free_end[1] > 0.0  # the free segment stops short of the surface
    assert a[1] > 0.0 > b[1]  # the contact segment crosses it
    assert np.linalg.norm(b - a) == pytest.approx(Settings().contact_resolution)
    assert abs(run.stop_point[1]) < 1e-6 and np.linalg.norm(sim.force) >= Settings().load_force


@pytest.mark.parametrize(
    ("terrain", "status", "side"),
    [(SLOPE_DOWN_RIGHT, Status.SLIP_LEFT, 1.0), (SLOPE_DOWN_LEFT, Status.SLIP_RIGHT, -1.0)],
)
def test_steep_slope_slips_to_the_correct_side_and_retreats(terrain, status, side):
    run, sim, _ = _execute(terrain, [[0.0, 0.3], [0.0, -0.1]])
    assert run.outcome is Outcome.CONTACT_FAILED
    assert run.history.status[-1] == status
    contact = 0.5 * (run.history.a[-1] + run.history.b[-1])
    assert np.sign(contact[0]) in (0.0, side)  # slid downhill before or during the test
    assert np.linalg.norm(sim.force) < 1e-9  # retreated into free space


V_TRAP = np.array([[0.5, 0.5], [0.0, 0.0], [-0.5, 0.5]])  # two 45 degree slopes, solid below
SLOPE_THEN_CLIFF = np.array([[0.5, -0.8], [0.5, -0.5], [-0.5, 0.5]])  # a wall drops at x = 0.5


def test_compliant_plan_follows_a_slide_into_a_vertex_trap_and_docks():
    loading = [[0.05, 0.3], [0.05, -0.1]]  # meets the right slope 5 cm from the vertex
    stiff, *_ = _execute(V_TRAP, loading, lateral_stiffness=25.0)
    assert stiff.outcome is Outcome.CONTACT_FAILED  # non-compliant: the slip ends the attempt
    run, sim, _ = _execute(V_TRAP, loading, compliant=True, lateral_stiffness=25.0)
    assert run.outcome is Outcome.DOCKED, run.detail
    assert np.linalg.norm(run.stop_point) < 0.005  # held at the vertex
    assert list(run.history.status) == [Status.FREE, Status.SLIP_RIGHT]  # the first contact
    contact = 0.5 * (run.history.a[-1] + run.history.b[-1])
    # on the right slope, between the first touch and the vertex (force-threshold detection)
    assert 0.0 < contact[0] <= 0.05 and contact[1] == pytest.approx(contact[0], abs=1e-3)
    assert SETTINGS.load_force <= np.linalg.norm(sim.force) < LIMITS.max_force


def test_compliant_slide_that_loses_contact_fails_and_retreats():
    run, sim, _ = _execute(
        SLOPE_THEN_CLIFF, [[0.4, 0.3], [0.4, -0.6]], compliant=True, lateral_stiffness=25.0
    )
    assert run.outcome is Outcome.CONTACT_FAILED and "lost contact" in run.detail, run.detail
    assert run.history.status[-1] == Status.SLIP_LEFT
    assert run.stop_point[0] > 0.48  # slid from x = 0.4 to the edge of the cliff
    assert np.linalg.norm(sim.force) < 3.0  # no more than the lateral spring's pull


# 45 then 57 degrees down to the right, then a wall: a slide from x = 0 crosses the 57 degree edge
# (clear of the 60 degrees where a piece within 30 degrees of the load gives no observation)
BENT_SLOPE_THEN_CLIFF = np.array([[0.13, -0.4], [0.1295, -0.1589], [0.075, -0.075], [-0.1, 0.1]])


def test_compliant_slide_reports_every_edge_it_crossed_before_falling_off():
    run, *_ = _execute(
        BENT_SLOPE_THEN_CLIFF, [[0.0, 0.2], [0.0, -0.5]], compliant=True, lateral_stiffness=25.0
    )
    assert run.outcome is Outcome.CONTACT_FAILED and "lost contact" in run.detail, run.detail
    # the first contact, then one row per evidence_spacing (4 cm) of the 10 cm 57-degree edge
    status = run.history.status
    assert status[0] == Status.FREE and np.all(status[1:] == Status.SLIP_LEFT)
    assert len(status) - 2 == 3, len(status)
    middles = 0.5 * (run.history.a[2:] + run.history.b[2:])
    assert middles.mean(axis=0) == pytest.approx([0.102, -0.117], abs=0.006)  # the edge's middle
    gaps = np.linalg.norm(np.diff(middles, axis=0), axis=1)
    assert np.all(gaps <= SETTINGS.evidence_spacing + 1e-9) and np.all(gaps > 0.02)
    direction = run.history.b[2:] - run.history.a[2:]
    np.testing.assert_allclose(direction, [[0.0, -SETTINGS.contact_resolution]] * len(direction))


def test_crossed_pieces_are_the_edges_between_the_trace_corners():
    from tactile_dock_ros.execution.guarded import crossed_pieces

    corner = np.array([[0.0, 0.0], [0.1, -0.1], [0.2, -0.3], [0.25, -0.3]])
    dense = np.vstack(
        [np.linspace(p, q, 20, endpoint=False) for p, q in itertools.pairwise(corner)]
    )
    trace = np.vstack([dense, corner[-1:]])
    right = np.array([1.0, 0.0])  # a slide down to the right pushed along -y: SLIP_LEFT
    pieces = np.array(crossed_pieces(trace, 0.01, right))
    np.testing.assert_allclose(pieces, [corner[1:3], corner[2:]], atol=1e-9)
    assert len(crossed_pieces(np.linspace([0, 0], [0.1, -0.1], 30), 0.01, right)[0]) == 0  # 1 piece
    assert len(crossed_pieces(trace, 0.06, right)[0]) == 1  # the 5 cm last piece is too short
    # past the lip the arm's lateral spring pulls the tool back down an undercut: not a slide
    undercut = np.vstack([trace, np.linspace([0.25, -0.3], [0.2, -0.4], 20)[1:]])
    np.testing.assert_allclose(crossed_pieces(undercut, 0.01, right), pieces, atol=1e-9)
    assert len(crossed_pieces(trace, 0.01, -right)[0]) == 0  # none of it slid the other way


def test_compliant_plan_sticks_at_once_on_a_floor_and_bounds_long_slides():
    run, *_ = _execute(FLOOR, [[0.0, 0.3], [0.0, -0.1]], compliant=True)
    assert run.outcome is Outcome.DOCKED and run.history.status[-1] == Status.STICK
    short = Settings(max_slide=0.05)
    run, *_ = _execute(
        SLOPE_THEN_CLIFF, [[0.4, 0.3], [0.4, -0.6]], settings=short, compliant=True,
        lateral_stiffness=25.0,
    )  # fmt: skip
    assert run.outcome is Outcome.CONTACT_FAILED and "max_slide" in run.detail


def test_a_non_compliant_plan_with_slide_on_slip_slides_for_evidence_but_never_docks():
    slide = Settings(slide_on_slip=True)
    loading = [[0.0, 0.2], [0.0, -0.5]]
    stiff, *_ = _execute(BENT_SLOPE_THEN_CLIFF, loading, lateral_stiffness=25.0)
    assert list(stiff.history.status) == [Status.FREE, Status.SLIP_LEFT]  # the slip ends it
    forces = []
    run, sim, _ = _execute(
        BENT_SLOPE_THEN_CLIFF, loading, settings=slide, lateral_stiffness=25.0, forces=forces
    )
    assert run.outcome is Outcome.CONTACT_FAILED and "lost contact" in run.detail, run.detail
    # the rows of a compliant slide: the first contact, then one per 4 cm of the 57-degree edge
    status = run.history.status
    assert status[0] == Status.FREE and np.all(status[1:] == Status.SLIP_LEFT)
    assert len(status) - 2 == 3, len(status)
    np.testing.assert_allclose(run.history.a[:2], stiff.history.a, atol=1e-3)  # same contact
    middles = 0.5 * (run.history.a[2:] + run.history.b[2:])
    assert middles.mean(axis=0) == pytest.approx([0.102, -0.117], abs=0.006)  # the edge's middle
    # force limits: the push pauses at the load force, never near the limit
    assert max(forces) < min(slide.load_force + 3.0, LIMITS.max_force)
    assert np.linalg.norm(sim.force) < 3.0  # retreated off the surface
    # a slide longer than max_slide stops there with the first contact as its only evidence
    short = Settings(slide_on_slip=True, max_slide=0.05)
    cut, *_ = _execute(BENT_SLOPE_THEN_CLIFF, loading, settings=short, lateral_stiffness=25.0)
    assert cut.outcome is Outcome.CONTACT_FAILED and "max_slide" in cut.detail, cut.detail
    assert list(cut.history.status) == [Status.FREE, Status.SLIP_LEFT]
    slid = float(cut.detail.split("slid ")[1].split(" m")[0])
    assert short.max_slide - 0.001 < slid < short.max_slide + 0.01


def test_a_non_compliant_slide_on_slip_into_a_vertex_trap_fails_with_the_first_contact():
    # the planner's non-compliant P_dock is of a first contact that sticks (core.simulate):
    # a slide that then sticks in a trap is not a dock, and shows only its first contact
    loading = [[0.05, 0.3], [0.05, -0.1]]  # meets the right slope 5 cm from the vertex
    forces = []
    run, *_ = _execute(
        V_TRAP, loading, settings=Settings(slide_on_slip=True), lateral_stiffness=25.0,
        forces=forces,
    )  # fmt: skip
    assert run.outcome is Outcome.CONTACT_FAILED and "stuck" in run.detail, run.detail
    assert "not a dock" in run.detail
    assert list(run.history.status) == [Status.FREE, Status.SLIP_RIGHT]
    assert np.linalg.norm(run.stop_point) < 0.03  # slid into the vertex, retreated from there
    assert max(forces) < LIMITS.max_force


def test_contact_on_a_prefix_move_is_a_collision():
    run, _, _ = _execute(FLOOR, [[0.3, 0.3], [0.3, -0.05], [0.0, -0.1]])
    assert run.outcome is Outcome.CONTACT_FAILED
    assert list(run.history.status) == [Status.FREE, Status.COLLIDE]
    assert "move 1" in run.detail


def test_loading_move_without_contact_reports_the_whole_path_free():
    run, _, _ = _execute(FLOOR, [[0.0, 0.5], [0.2, 0.4], [0.2, 0.2]])
    assert run.outcome is Outcome.NO_CONTACT
    assert list(run.history.status) == [Status.FREE, Status.FREE]
    np.testing.assert_allclose(run.stop_point, [0.2, 0.2], atol=Settings().waypoint_tolerance)


def test_a_far_first_waypoint_is_reached_by_an_extra_move():
    run, _, _ = _execute(FLOOR, [[0.0, 0.3], [0.0, -0.1]], start=[0.2, 0.5])
    assert run.outcome is Outcome.DOCKED
    assert list(run.history.status) == [Status.FREE, Status.FREE, Status.STICK]


def test_a_plan_of_many_short_waypoints_finishes_within_its_time_budget():
    """Each waypoint is approached exponentially (``move_seconds``): 40 waypoints 6 mm apart
    take ~11 s at 0.2 m/s (13.5 s in the simulator), more than 3 x length / speed + margin
    (8.6 s, the old budget that ABORTED such a plan in the node suite). The budget counts the
    approaches."""
    waypoints = np.column_stack([np.linspace(0.0, 0.24, 41), np.full(41, 0.3)])
    run, _, commanded = _execute(FLOOR, waypoints, speed=0.2)
    assert run.outcome is Outcome.NO_CONTACT, run.detail  # the loading move ends in the air
    ideal = move_seconds(waypoints, 0.2, SETTINGS)
    assert len(commanded) * DT > 3 * 0.24 / 0.2 + SETTINGS.time_margin  # the old budget
    assert ideal < len(commanded) * DT < 1.5 * ideal  # the model, and the sim's lag behind it


def test_commands_never_exceed_the_speed_limit():
    limits = Limits(LIMITS.workspace_min, LIMITS.workspace_max, 0.05, 40.0, 0.5)
    run, _, commanded = _execute(FLOOR, [[0.0, 0.3], [0.0, -0.1]], limits=limits, speed=0.05)
    speeds = np.linalg.norm(commanded, axis=1)
    assert speeds.max() <= 0.05 + 1e-12 and run.max_speed_commanded <= 0.05 + 1e-12


@pytest.mark.parametrize(
    ("waypoints", "speed", "limits", "match"),
    [
        ([[0.0, 0.3], [0.0, -0.1]], 0.5, LIMITS, "speed"),
        ([[0.0, 0.3], [0.0, -0.95]], 0.1, LIMITS, "outside the workspace"),
        (
            [[0.0, 0.3], [0.0, -0.1]],
            0.1,
            Limits(LIMITS.workspace_min, LIMITS.workspace_max, 0.2, 5.0, 0.5),
            "force limit",
        ),
    ],
)
def test_plans_outside_the_limits_are_refused_without_moving(waypoints, speed, limits, match):
    run = GuardedRun(_plan(waypoints, speed), np.array([0.0, 0.3]), limits, Settings(), 0.0)
    assert run.done and run.outcome is Outcome.ABORTED and match in run.detail
    assert np.all(run.step(0.0, np.array([0.0, 0.3]), np.zeros(2), 0.0) == 0.0)


def test_sensor_timeout_aborts_with_zero_command():
    run = GuardedRun(_plan([[0.0, 0.3], [0.0, -0.1]]), np.array([0.0, 0.3]), LIMITS, Settings(), 0)
    assert np.any(run.step(0.0, np.array([0.0, 0.3]), np.zeros(2), 0.0) != 0)
    velocity = run.step(0.1, np.array([0.0, 0.29]), np.zeros(2), sensor_age=0.6)
    assert np.all(velocity == 0) and run.outcome is Outcome.ABORTED
    assert "sensor timeout" in run.detail


def test_force_above_the_limit_and_leaving_the_box_abort():
    start = np.array([0.0, 0.3])
    run = GuardedRun(_plan([[0.0, 0.3], [0.0, -0.1]]), start, LIMITS, Settings(), 0.0)
    assert np.all(run.step(0.0, start, np.array([0.0, 41.0]), 0.0) == 0)
    assert run.outcome is Outcome.ABORTED and "force" in run.detail
    run = GuardedRun(_plan([[0.0, 0.3], [0.0, -0.1]]), start, LIMITS, Settings(), 0.0)
    assert np.all(run.check_next(np.array([0.0, 0.899]), np.array([0.0, 0.2]), DT) == 0)
    assert run.outcome is Outcome.ABORTED and "workspace" in run.detail


def test_force_filter_removes_the_bias_and_smooths_noise():
    rng = np.random.default_rng(0)
    bias = np.array([0.4, -0.3])
    flt = ForceFilter(cutoff_hz=5.0, bias_samples=20)
    for i in range(20):
        assert not flt.ready
        flt.add(i * 0.005, bias + rng.normal(0, 0.05, 2))
    assert flt.ready and np.allclose(flt.bias, bias, atol=0.05)
    for i in range(20, 400):
        flt.add(i * 0.005, bias + np.array([0.0, 2.0]) + rng.normal(0, 0.5, 2))
    np.testing.assert_allclose(flt.value, [0.0, 2.0], atol=0.3)


def test_a_blocked_retreat_stops_at_the_contact_threshold():
    """The retreat backs off along -d; when a face resists it (force along +d above the
    plan's 3 N threshold) it ends there instead of pushing on to the 40 N limit."""

    def retreat(blocked_at):
        plan = _plan([[0.0, 0.1], [0.0, -0.5], [0.5, -0.5]])  # a prefix move, then loading
        run = GuardedRun(plan, np.array([0.0, 0.1]), LIMITS, SETTINGS, 0.0)
        tool, t = np.array([0.0, 0.0]), 0.0
        run.step(t, tool, np.array([0.0, 5.0]), 0.0)  # collided: the floor pushes back up
        assert run._phase.value == "retreat"
        peak = 0.0
        while not run.done and t < 10:
            t += DT
            wall = max(tool[1] - blocked_at, 0.0) * 500.0  # a face above: pushes down (+d)
            force = np.array([0.0, -wall])
            peak = max(peak, wall)
            tool = tool + run.step(t, tool, force, 0.0) * DT
        return run, tool[1], peak

    free, y, _ = retreat(1.0)
    assert free.outcome is Outcome.CONTACT_FAILED and y == pytest.approx(0.02, abs=0.002)
    blocked, y, peak = retreat(0.01)
    assert blocked.outcome is Outcome.CONTACT_FAILED and "retreat blocked" in blocked.detail
    assert y < 0.02 and peak < 3.0 + 500.0 * 0.1 * DT + 1e-9, peak


@pytest.mark.parametrize("wall", ["released", "pressing", "jammed", "growing"])
def test_a_tool_still_pressed_after_the_retreat_moves_along_the_force_until_released(wall):
    """A soft-across arm can end the retreat pressed sideways against a face (3 N along +x,
    across the move): the next plan's F/T bias would absorb it. The tool then moves along
    the force until it falls to a quarter of the 3 N threshold (``released``: at x = 6 mm),
    for at most the retreat distance (``pressing``: never) or the time that takes plus 1 s
    (``jammed``: the tool cannot move), with that time added to the plan's budget (here
    nearly spent at the contact): no abort. A force that grows on the way (``growing``: the
    reading does not point out of the surface) ends it at once."""
    plan = _plan([[0.0, 0.1], [0.0, -0.5], [0.5, -0.5]])
    run = GuardedRun(plan, np.array([0.0, 0.1]), LIMITS, SETTINGS, 0.0)
    budget = 3 * move_seconds(plan.waypoints, 0.1, SETTINGS) + SETTINGS.time_margin
    tool, t = np.array([0.0, 0.0]), budget - 0.3
    run.step(t, tool, np.array([3.0, 4.0]), 0.0)  # collided on the prefix move
    pressed_until = 0.006 if wall == "released" else np.inf
    force, released_at = np.zeros(2), None
    while not run.done and t < budget + 10:
        t += DT
        force = np.array([3.0 if tool[0] < pressed_until else 0.0, 0.0])
        if wall == "growing":
            force[0] += 100.0 * tool[0]  # 1 N per cm moved
        velocity = run.step(t, tool, force, 0.0)
        if wall != "jammed" or velocity[0] == 0.0:  # jammed: no way along +x
            tool = tool + velocity * DT
        released_at = t if run.done else released_at
    assert run.outcome is Outcome.CONTACT_FAILED, run.detail
    assert tool[1] == pytest.approx(SETTINGS.retreat_distance, abs=0.003)  # retreated first
    if wall == "released":
        assert "released after" in run.detail and np.linalg.norm(force) == 0.0
        assert 0.006 <= tool[0] < 0.007
    elif wall == "growing":
        assert "grew to 3.0 N in contact after 0.000 m" in run.detail, run.detail
        assert 0.0 < tool[0] < 0.001
    else:
        assert "still 3.0 N in contact" in run.detail
        moved = SETTINGS.retreat_distance if wall == "pressing" else 0.0
        assert tool[0] == pytest.approx(moved, abs=0.001)
        # pressing: the distance at the loading speed; jammed: that time plus 1 s
        assert released_at - (budget - 0.3) < 0.2 + 1.0 + (wall == "jammed") + 0.1


def test_released_fraction_sets_when_a_pressed_tool_counts_as_free():
    """With ``released_fraction`` 1 the 3 N left after the retreat is within the 3 N threshold:
    no release (the default 0.25 releases it, test above)."""
    plan = _plan([[0.0, 0.1], [0.0, -0.5], [0.5, -0.5]])
    lenient = Settings(released_fraction=1.0)
    run = GuardedRun(plan, np.array([0.0, 0.1]), LIMITS, lenient, 0.0)
    tool, t = np.array([0.0, 0.0]), 0.0
    run.step(t, tool, np.array([3.0, 4.0]), 0.0)
    while not run.done and t < 10:
        t += DT
        tool = tool + run.step(t, tool, np.array([3.0, 0.0]), 0.0) * DT
    assert run.detail == "collided on move 1" and tool[0] == 0.0


def test_a_retreat_blocked_at_once_releases_along_the_force():
    """The contact force already pushes along the move (something behind the tool: in the
    node suite, a plan started pressed against a face): the retreat is blocked at 0 m and the
    tool moves along the force, here free 5 mm further on."""
    plan = _plan([[0.0, 0.1], [0.0, -0.5], [0.5, -0.5]])
    run = GuardedRun(plan, np.array([0.0, 0.1]), LIMITS, SETTINGS, 0.0)
    tool, t = np.array([0.0, 0.0]), 0.0
    run.step(t, tool, np.array([0.0, -4.0]), 0.0)  # 4 N along the move d = (0, -1)
    assert run._phase.value == "release"
    while not run.done and t < 10:
        t += DT
        force = np.array([0.0, -4.0 if tool[1] > -0.005 else 0.0])
        tool = tool + run.step(t, tool, force, 0.0) * DT
    assert "retreat blocked after 0.000 m; released after 0.005 m" in run.detail
    assert run.outcome is Outcome.CONTACT_FAILED and -0.006 < tool[1] <= -0.005


def test_mock_tool_sticks_inside_and_slides_outside_the_friction_cone():
    sim = PointToolSim(FLOOR, False, 0.5, 500.0, [0.0, 0.01])
    for _ in range(40):  # push down and 20 degrees sideways: inside the cone (26.6 degrees)
        sim.step(0.1 * np.array([np.sin(0.35), -np.cos(0.35)]), DT)
    assert sim.tool[0] == pytest.approx(0.01 * np.tan(0.35), abs=1e-9)
    x_stuck = sim.tool[0]
    for _ in range(40):  # 45 degrees: outside, slides along +x
        sim.step(0.1 * np.array([1.0, -1.0]) / np.sqrt(2), DT)
    assert sim.tool[0] > x_stuck + 0.01 and sim.tool[1] == pytest.approx(0.0, abs=1e-12)
    f = sim.force
    assert abs(f[0]) == pytest.approx(0.5 * f[1], rel=1e-6)  # on the cone boundary


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)), min_size=1, max_size=60))
def test_mock_tool_never_enters_the_solid(velocities):
    notch = np.array([[0.5, -0.1], [0.1, 0.0], [0.05, -0.08], [-0.05, 0.02], [-0.5, 0.1]])
    sim = PointToolSim(notch, False, 0.4, 500.0, [0.0, 0.3])
    for v in velocities:
        for _ in range(5):
            sim.step(np.array(v), DT)
            below = np.interp(sim.tool[0], notch[::-1, 0], notch[::-1, 1])
            assert sim.tool[1] >= below - 1e-9


def test_lateral_compliance_makes_a_marginal_slope_slip_far():
    """28 degrees against a 26.6 degree friction cone: a stiff arm barely moves, a laterally
    compliant one slides (paper Sec. III-A2), so the stick/slip test can tell."""
    angle = np.deg2rad(28.0)
    slope = np.array([[np.cos(angle), -np.sin(angle)], [-np.cos(angle), np.sin(angle)]])
    slides = {}
    for lateral in (500.0, 25.0):
        sim = PointToolSim(slope, False, 0.5, 500.0, [0.0, 0.01], lateral_stiffness=lateral)
        for _ in range(300):
            sim.step([0.0, -0.05], DT)
        slides[lateral] = abs(sim.tool[0])
        below = np.interp(sim.tool[0], slope[::-1, 0], slope[::-1, 1])
        assert sim.tool[1] >= below - 1e-9
    assert slides[500.0] < 0.01 < 0.05 < slides[25.0]


def test_a_new_motion_direction_keeps_the_contact_force_continuous():
    """After a slip on a 35 degree slope and a 2 cm retreat the laterally compliant arm is
    still deflected across its motion (about 4 cm at 25 N/m). Turning to any new direction keeps
    the force (bumpless): it used to jump to ~20 N in one step, 40 N after longer slides."""
    angle = np.deg2rad(35.0)
    slope = np.array([[np.cos(angle), -np.sin(angle)], [-np.cos(angle), np.sin(angle)]])
    sim = PointToolSim(slope, False, 0.5, 500.0, [0.0, 0.1], 25.0, 0.3)  # config/mock.yaml's
    while np.linalg.norm(sim.force) < 12.0:
        sim.step([0.0, -0.03], 0.005)
    anchor = sim.tool.copy()
    while anchor[1] - sim.tool[1] > -0.02:
        sim.step([0.0, 0.2], 0.005)
    before = np.linalg.norm(sim.force)
    assert 0.5 < before < 3.0 and np.linalg.norm(sim.setpoint - sim.tool) > 0.03  # deflected
    # sideways, diagonal, back down 16 degrees off the reverse (a retreat or a release along
    # the force after a deflected move) and steering by 10 and 20 degrees: any turn of the stiff
    # axis under the deflection used to jump the force (20 degrees: 1.3 -> 5.9 N)
    turns = ([1.0, 0.0], [-1.0, 0.0], [0.7071, -0.7071], [0.2756, -0.9613])
    for turn in (*turns, [0.1736, 0.9848], [0.3420, 0.9397]):
        turned = copy.deepcopy(sim)
        turned.step(0.2 * np.array(turn), 0.005)
        assert np.linalg.norm(turned.force) < before + 0.2 * 500.0 * 0.005 + 1e-9, turn


def test_tool_slides_off_the_end_of_an_open_polyline():
    ramp = np.array([[0.1, -0.2], [-0.1, 0.0]])  # 45 degrees, lower end at (0.1, -0.2)
    sim = PointToolSim(ramp, False, 0.5, 500.0, [0.0, 0.2], lateral_stiffness=25.0)
    for _ in range(700):
        sim.step([0.0, -0.1], DT)
    assert sim.tool[1] < -0.2 and np.linalg.norm(sim.force) < 1e-9  # free, past the end


def test_compliant_slides_over_overhanging_lips_report_only_what_the_truth_shows():
    # sloper's holds overhang: past the lip the arm's lateral spring pulls the tool down the
    # undercut, which must not be reported as more slip along the slope
    from tactile_dock_ros.core import problems, slides

    problem, rng = problems.get("sloper"), np.random.default_rng(7)
    slid_far = 0
    for _ in range(20):
        truth = problem.sample_ground_truth(rng)
        truth = truth - 0.5 * (truth.min(0) + truth.max(0))
        lo, hi = truth.min(0), truth.max(0)
        limits = Limits(lo - 0.5, hi + 0.5, 0.2, 40.0, 0.5)
        for x in rng.uniform(lo[0], hi[0], 3):
            path = [[x, hi[1] + 0.05], [x, lo[1] - 0.1]]
            run, *_ = _execute(truth, path, limits, compliant=True, lateral_stiffness=25.0)
            history = run.history
            slip = np.isin(history.status, [Status.SLIP_LEFT, Status.SLIP_RIGHT])
            slid_far += slip.sum() >= 2
            ids = np.ones(len(history))
            assert slides.consistent_with_slides(
                truth[None], False, history, ids, problem.load, problem.friction
            )[0]
    assert slid_far >= 3  # the check saw slides that crossed whole edges
