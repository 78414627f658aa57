"""Message <-> numpy/core conversion: exact round trips and clear errors on malformed input."""

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from std_msgs.msg import Header
from tactile_dock_ros.msg import (
    ContactSegment,
    DockingPlan,
    EpisodeCycle,
    EpisodeStatus,
    ExecutionReport,
)

from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.execution.types import Outcome, PlanCommand, PlaneFrame, Report
from tactile_dock_ros.nodes import convert, validate
from tactile_dock_ros.nodes.convert import MessageError

HEADER = Header(frame_id="dock_plane")


def _shape(rng, n=5, m=3, closed=False):
    return GaussianShape(rng.normal(size=2 * n), rng.normal(size=(2 * n, m)), closed, 0.7)


def _history():
    return History(
        [[0.0, 1.0], [0.0, 0.1], [0.2, 0.3]],
        [[0.0, 0.1], [0.0, 0.09], [0.2, 0.25]],
        [Status.FREE, Status.STICK, Status.SLIP_RIGHT],
    )


def _plan(**changes):
    fields = dict(
        plan_id=3,
        dock=True,
        waypoints=np.array([[0.0, 0.5], [0.1, 0.2], [0.1, -0.1]]),
        load=np.array([0.0, -1.0]),
        force_threshold=3.0,
        max_speed=0.1,
        compliant=False,
        p_dock=0.4,
        objective=0.3,
        target_edge=4,
        reason="best site",
        target_point=np.array([0.1, 0.05]),
        episode=12,
    )
    fields.update(changes)
    return PlanCommand(**fields)


def test_shape_round_trip_is_exact():
    shape = _shape(np.random.default_rng(0), closed=True)
    back = convert.shape_from_msg(convert.shape_to_msg(shape, HEADER))
    np.testing.assert_array_equal(back.mean, shape.mean)
    np.testing.assert_array_equal(back.basis, shape.basis)
    assert back.closed and back.friction == shape.friction
    tailed = GaussianShape(shape.mean, shape.basis, False, 0.5, closure_edges=(0, 3))
    assert convert.shape_from_msg(convert.shape_to_msg(tailed, HEADER)).closure_edges == (0, 3)


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("mean", [0.0] * 9, "mean has 9 values"),
        ("basis", [0.0] * 5, "basis has 5 values"),
        ("num_vertices", 1, "num_vertices"),
        ("mean", [np.nan] + [0.0] * 9, "NaN"),
        ("basis", [np.inf] + [0.0] * 29, "NaN or inf"),
        ("friction", -0.1, "friction"),
        ("closure_edges", [4], "closure_edges"),
    ],
)
def test_malformed_shape_is_rejected(field, value, match):
    msg = convert.shape_to_msg(_shape(np.random.default_rng(1)), HEADER)
    setattr(msg, field, value)
    with pytest.raises(MessageError, match=match):
        convert.shape_from_msg(msg)


def test_history_round_trip_keeps_order_status_and_plan_ids():
    history = _history()
    state = EpisodeState(history, [1, 1, 2], tool=[0.0, 0.4]).sampled(dropped=[0])
    msg = convert.history_to_msg(state, HEADER)
    assert [s.plan_id for s in msg.segments] == [1, 1, 2]
    back = convert.history_from_msg(msg)
    assert back.move_ids.tolist() == [1, 1, 2] and back.tool is None
    np.testing.assert_array_equal(back.history.a, history.a)
    np.testing.assert_array_equal(back.history.b, history.b)
    np.testing.assert_array_equal(back.history.status, history.status)
    into = convert.history_from_msg(convert.history_to_msg(EpisodeState(), HEADER), state)
    assert len(into.history) == 0 and into.dropped.tolist() == []  # its rows, none dropped
    assert into.tool.tolist() == [0.0, 0.4]  # the rest of the state is kept


def test_empty_history_converts_both_ways():
    assert len(convert.history_from_segments([])) == 0
    assert convert.history_to_msg(EpisodeState(), HEADER).segments == []


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda s: setattr(s, "status", 9), "unknown contact status"),
        (lambda s: setattr(s.end, "x", float("nan")), "NaN"),
        (lambda s: setattr(s, "end", s.start), "zero length"),
    ],
)
def test_malformed_segment_is_rejected(change, match):
    segments = convert.history_to_msg(EpisodeState(_history()), HEADER).segments
    change(segments[1])
    with pytest.raises(MessageError, match=match):
        convert.history_from_segments(segments)


def test_samples_round_trip_and_size_checks():
    vertices = np.random.default_rng(2).normal(size=(4, 6, 2))
    msg = convert.samples_to_msg(vertices, HEADER, "hmc", 3.5, 7, [2], 0.25)
    np.testing.assert_array_equal(convert.samples_from_msg(msg), vertices)
    assert (msg.history_length, list(msg.dropped_segments)) == (7, [2])
    msg.num_samples = 5
    with pytest.raises(MessageError, match="expected num_samples"):
        convert.samples_from_msg(msg)
    msg.num_samples, msg.samples = 0, []
    with pytest.raises(MessageError, match="num_samples >= 1"):
        convert.samples_from_msg(msg)


def test_sample_request_round_trip_and_bad_fields():
    msg = convert.sample_request_to_msg(Header(), 77, 2**62 + 5, 3, 12, 400)
    assert convert.sample_request_from_msg(msg) == {
        "episode": 77, "nonce": 2**62 + 5, "hold_id": 3, "history_length": 12, "num_samples": 400,
    }  # fmt: skip
    for field, value, match in [
        ("episode", 0, "episode id 0"),
        ("history_length", 0, "history_length >= 1"),
        ("num_samples", 2, "num_samples >= 3"),
        ("num_samples", validate.MAX_SAMPLES + 1, "num_samples is"),
        ("history_length", validate.MAX_SEGMENTS + 1, "history_length is"),
    ]:
        bad = convert.sample_request_to_msg(Header(), 77, 1, 3, 12, 400)
        setattr(bad, field, value)
        with pytest.raises(MessageError, match=match):
            convert.sample_request_from_msg(bad)


def test_plan_round_trip():
    plan = _plan()
    back = convert.plan_from_msg(convert.plan_to_msg(plan, HEADER))
    np.testing.assert_array_equal(back.waypoints, plan.waypoints)
    assert (back.plan_id, back.dock, back.target_edge, back.reason) == (3, True, 4, "best site")
    assert back.episode == plan.episode == 12
    assert back.force_threshold == 3.0 and back.max_speed == 0.1
    np.testing.assert_array_equal(back.target_point, plan.target_point)


@pytest.mark.parametrize(
    ("plan", "match"),
    [
        (_plan(waypoints=np.zeros((1, 2))), ">= 2 waypoints"),
        (_plan(waypoints=np.array([[0.0, 0.5], [0.1, 0.2], [0.1, 0.2]])), "zero length"),
        (_plan(load=np.array([0.0, -2.0])), "unit vector"),
        (_plan(max_speed=0.0), "must be > 0"),
        (_plan(load=np.array([0.6, -0.8])), "does not point along load_direction"),
        (_plan(waypoints=np.array([[0.0, np.nan], [0.1, 0.2]])), "NaN"),
    ],
)
def test_malformed_dock_plan_is_rejected(plan, match):
    with pytest.raises(MessageError, match=match):
        convert.plan_from_msg(convert.plan_to_msg(plan, HEADER))


def test_give_up_plan_needs_no_waypoints_but_decision_must_be_known():
    msg = convert.plan_to_msg(_plan(dock=False, waypoints=np.zeros((0, 2))), HEADER)
    assert msg.decision == DockingPlan.GIVE_UP
    assert not convert.plan_from_msg(msg).dock
    msg.decision = 7
    with pytest.raises(MessageError, match="unknown decision"):
        convert.plan_from_msg(msg)


def test_report_round_trip_and_unknown_outcome():
    report = Report(
        5, ExecutionReport.CONTACT_FAILED, _history(), np.array([0.1, 0.2]), "x", episode=9
    )
    msg = convert.report_to_msg(report, HEADER)
    assert all(s.plan_id == 5 for s in msg.segments)
    back = convert.report_from_msg(msg)
    assert back.outcome_name == "CONTACT_FAILED" and back.detail == "x" and back.episode == 9
    np.testing.assert_array_equal(back.history.status, report.history.status)
    msg.outcome = 42
    with pytest.raises(MessageError, match="unknown outcome"):
        convert.report_from_msg(msg)


def test_message_constants_match_the_ros_free_types():
    assert {s.name: s.value for s in Status} == _constants(ContactSegment)
    assert {o.name: o.value for o in Outcome} == _constants(ExecutionReport)
    assert dict(zip(convert.EPISODE_STATES, range(6), strict=True)) == _constants(EpisodeStatus)
    assert not {o.value for o in Outcome} & set(_constants(EpisodeCycle).values())


def _constants(msg_type) -> dict[str, int]:
    """The integer constants a message type defines, by name."""
    return {n: v for n, v in vars(msg_type).items() if n.isupper() and isinstance(v, int)}


def test_episode_status_round_trip_and_unknown_state():
    cycles = [
        {"p_dock": 0.5, "inference_s": 1.5, "planning_s": 0.25, "execution_s": 3.0,
         "outcome": "CONTACT_FAILED", "plan_stamp": 12.0},
        {"p_dock": 0.75, "inference_s": 1.0, "planning_s": 0.5, "execution_s": 2.0,
         "outcome": convert.INTERRUPTED},
        {"p_dock": 0.25, "inference_s": 0.5, "planning_s": 0.125, "outcome": ""},  # executing
    ]  # fmt: skip
    msg = convert.episode_status_to_msg(HEADER, "RUNNING", 7, "resumed", 12, cycles)
    assert (msg.state, msg.detail, msg.prior_vertices) == (EpisodeStatus.RUNNING, "resumed", 12)
    assert [c.outcome for c in msg.cycles] == [1, EpisodeCycle.INTERRUPTED, EpisodeCycle.PENDING]
    assert convert.episode_status_from_msg(msg) == ("RUNNING", 7)
    back = convert.episode_cycles_from_msg(msg)
    keys = ("p_dock", "inference_s", "planning_s", "execution_s", "outcome")
    assert back[:2] == [{k: c[k] for k in keys} for c in cycles[:2]]
    assert back[2] == {k: cycles[2].get(k) for k in keys}  # execution_s None: no report yet
    msg.state = 9
    with pytest.raises(MessageError, match="unknown episode state"):
        convert.episode_status_from_msg(msg)
    msg.cycles[0].outcome = 7
    with pytest.raises(MessageError, match="unknown cycle outcome"):
        convert.episode_cycles_from_msg(msg)


def _vertical_plane():
    return PlaneFrame(np.array([0.1, 0.6, -0.2]), np.eye(3)[0], np.eye(3)[2])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=2, max_size=2))
def test_plane_points_round_trip(xy):
    plane = _vertical_plane()
    p2 = np.array(xy)
    np.testing.assert_allclose(plane.point_to_plane(plane.point_from_plane(p2)), p2, atol=1e-12)
    np.testing.assert_allclose(plane.vector_to_plane(plane.vector_from_plane(p2)), p2, atol=1e-12)


def test_hold_evaluations_become_messages_and_tool_points_are_checked():
    from geometry_msgs.msg import Point
    from tactile_dock_ros.msg import HoldEvaluation as Msg

    from tactile_dock_ros.core.holds import HoldEvaluation

    found = HoldEvaluation("dock", np.array([0.1, -0.2]), 0.8, 0.7, 4, "ours: edge 4", 0.02)
    msg = convert.hold_evaluation_to_msg(3, found, HEADER)
    assert (msg.hold_id, msg.found, msg.decision, msg.target_edge) == (3, True, Msg.DOCK, 4)
    assert (msg.site.x, msg.site.y, msg.site.z) == (0.1, -0.2, 0.0)
    assert (msg.site_docking_probability, msg.path_docking_probability) == (0.8, 0.7)
    assert msg.reason == "ours: edge 4" and msg.compute_time == 0.02 and msg.header == HEADER
    failed = convert.hold_not_evaluated_msg(3, "not evaluated: bad prior", HEADER)
    assert failed.found and failed.decision == Msg.GIVE_UP and failed.target_edge == -1
    assert np.isnan(failed.site.x) and failed.reason == "not evaluated: bad prior"
    missing = convert.hold_not_evaluated_msg(9, "no hold 9 (kept: [1, 2])")
    assert not missing.found and missing.reason == "no hold 9 (kept: [1, 2])"
    np.testing.assert_array_equal(
        convert.point_xy("tool", Point(x=0.3, y=-0.1, z=5.0)), [0.3, -0.1]
    )
    for bad in (Point(x=np.nan), Point(y=2 * validate.MAX_COORDINATE_M)):
        with pytest.raises(MessageError, match="tool"):
            convert.point_xy("tool", bad)


def test_plane_axes_must_be_orthonormal():
    with pytest.raises(ValueError, match="orthonormal"):
        PlaneFrame(np.zeros(3), np.array([1.0, 0, 0]), np.array([1.0, 1.0, 0]))


def test_pose_and_wrench_map_into_the_plane():
    from geometry_msgs.msg import PoseStamped, WrenchStamped

    plane = _vertical_plane()
    pose = PoseStamped()
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = 0.3, 5.0, 0.4
    np.testing.assert_allclose(convert.pose_position(pose, plane), [0.2, 0.6])
    wrench = WrenchStamped()
    wrench.wrench.force.z = float("inf")
    with pytest.raises(MessageError, match="wrench"):
        convert.wrench_force(wrench)


def test_hardware_messages_round_trip_and_frames_are_checked():
    header = convert.Header(frame_id="base_link")
    pose = convert.pose_to_msg(np.array([0.1, 0.2, 0.3]), header)
    np.testing.assert_array_equal(convert.pose_rotation(pose), np.eye(3))
    force = np.array([1.0, -2.0, 3.0])
    np.testing.assert_array_equal(convert.wrench_force(convert.wrench_to_msg(force, header)), force)
    twist = convert.twist_to_msg(np.array([0.01, 0.0, -0.02]), header)
    np.testing.assert_array_equal(convert.twist_velocity(twist, _vertical_plane()), [0.01, -0.02])
    validate.check_frame("pose", pose, "base_link")
    pose.header.frame_id = "tool0"
    with pytest.raises(MessageError, match="'tool0', expected 'base_link'"):
        validate.check_frame("pose", pose, "base_link")
    pose.pose.orientation.x, pose.pose.orientation.w = 1.0, 1.0  # not normalized
    with pytest.raises(MessageError, match="unit quaternion"):
        convert.pose_rotation(pose)
    np.testing.assert_array_equal(convert.pose_orientation(pose), [1.0, 0.0, 0.0, 1.0])
    pose.pose.orientation.y = np.nan
    for read in (convert.pose_orientation, convert.pose_rotation):
        with pytest.raises(MessageError, match=r"pose\.orientation"):
            read(pose)
    pose.pose.orientation.y = 0.0
    pose.pose.orientation.x, pose.pose.orientation.w = 0.0, 0.0
    pose.pose.orientation.z = 1.0  # half a turn about z
    np.testing.assert_allclose(convert.pose_rotation(pose) @ [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0])


@pytest.mark.parametrize("value", [1e300, -1e7, 1e150])
def test_absurd_poses_wrenches_and_samples_are_refused(value):
    from geometry_msgs.msg import PoseStamped, WrenchStamped

    pose = PoseStamped()
    pose.pose.orientation.w = 1.0
    pose.pose.position.y = value
    with pytest.raises(MessageError, match=r"pose\.position has a value beyond"):
        convert.pose_position(pose, _vertical_plane())
    for field, name in (("force", "wrench.force"), ("torque", "wrench.torque")):
        wrench = WrenchStamped()
        getattr(wrench.wrench, field).x = value
        with pytest.raises(MessageError, match=rf"{re.escape(name)} has a value beyond"):
            convert.wrench_force(wrench)
    samples = convert.samples_to_msg(np.full((2, 3, 2), value), HEADER, "hmc", 1.0, 0)
    with pytest.raises(MessageError, match="samples has a value beyond"):
        convert.samples_from_msg(samples)


def test_poses_and_wrenches_within_the_bounds_pass():
    header = convert.Header(frame_id="base_link")
    edge = np.array([validate.MAX_COORDINATE_M, 0.0, -validate.MAX_COORDINATE_M])
    pose = convert.pose_to_msg(edge, header)
    assert np.all(np.isfinite(convert.pose_position(pose, _vertical_plane())))
    force = np.array([validate.MAX_FORCE_N, -validate.MAX_FORCE_N, 0.0])
    np.testing.assert_array_equal(convert.wrench_force(convert.wrench_to_msg(force, header)), force)
