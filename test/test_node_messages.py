"""Malformed messages are logged and dropped without corrupting a node's state (in-process)."""

import dataclasses
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from node_helpers import launch_nodes, node_with_driver, planner_episode, pose_msg
from ros_helpers import spin_until
from tactile_dock_ros.msg import DockingPlan, EpisodeStatus, ExecutionReport

from tactile_dock_ros.execution.types import PRODUCER_LOST, PlanCommand, Report
from tactile_dock_ros.nodes import convert, executor_node, qos

pytestmark = pytest.mark.dds


def _plan_msg(plan_id, waypoints):
    command = PlanCommand(
        plan_id, True, np.array(waypoints, float), np.array([0.0, -1.0]), 3.0, 0.1, False,
        0.5, 0.5, 0, "",
    )  # fmt: skip
    return convert.plan_to_msg(command, convert.Header(frame_id="dock_plane"))


def test_executor_drops_malformed_input_and_aborts_on_missing_sensors(tmp_path):
    spec = launch_nodes("mock")["executor"]
    reports, commands = [], []
    with node_with_driver(spec, tmp_path, ["-p", "executor:connect_timeout:=1.0"]) as (
        node, driver, executor,
    ):  # fmt: skip
        plans = driver.create_publisher(DockingPlan, "plan", qos.EVENTS)
        poses = driver.create_publisher(PoseStamped, "/arm/tool_pose", qos.SENSOR)
        wrenches = driver.create_publisher(WrenchStamped, "/ft_sensor/wrench", qos.SENSOR)
        driver.create_subscription(ExecutionReport, "execution_report", reports.append, qos.EVENTS)
        driver.create_subscription(TwistStamped, "/arm/cmd_twist", commands.append, qos.COMMAND)
        assert spin_until(executor, lambda: plans.get_subscription_count() > 0, 10.0)

        # A NaN pose and a NaN wrench are dropped: the tool stays unknown, no bias sample counted.
        poses.publish(pose_msg(float("nan"), 0.6, 0.3))
        wrench = WrenchStamped()
        wrench.wrench.force.x = float("nan")
        wrenches.publish(wrench)
        # A malformed plan (NaN waypoint) never runs and gets no report ...
        plans.publish(_plan_msg(1, [[0.0, np.nan], [0.0, 0.1]]))
        # ... so the next valid one is not "busy"; without a pose it aborts on the timeout. The
        # planner's resent copy of a plan (same id and stamp) is ignored, not refused as busy.
        second_plan = _plan_msg(2, [[0.0, 0.3], [0.0, 0.1]])
        plans.publish(second_plan)
        plans.publish(second_plan)
        assert spin_until(executor, lambda: len(reports) == 1, 10.0)
        assert node.tool is None and not node.filter.ready and node.filter._count == 0
        first = convert.report_from_msg(reports[0])
        assert first.plan_id == 2 and first.outcome == ExecutionReport.ABORTED
        assert "no tool pose" in first.detail

        # With a pose but no F/T data the plan waits for it, then aborts with a zero command.
        assert spin_until(executor, lambda: node.tool is not None or poses.publish(
            pose_msg(0.0, 0.6, 0.3)), 10.0)  # fmt: skip
        plans.publish(_plan_msg(3, [[0.0, 0.3], [0.0, 0.1]]))
        assert spin_until(executor, lambda: len(reports) == 2, 10.0)
        second = convert.report_from_msg(reports[1])
        assert second.plan_id == 3 and second.outcome == ExecutionReport.ABORTED
        assert "no wrench" in second.detail
        assert spin_until(executor, lambda: _zero(commands[-1]), 5.0)  # the arm is stopped

        # Sensors that stop while a plan runs: the arm is stopped, the report says why.
        def feed():
            poses.publish(pose_msg(0.0, 0.6, 0.3))
            wrenches.publish(WrenchStamped())
            return node.run is not None and node.filter.ready and not _zero(commands[-1])

        plans.publish(_plan_msg(4, [[0.0, 0.3], [0.0, 0.1]]))
        assert spin_until(executor, feed, 10.0)
        assert spin_until(executor, lambda: len(reports) == 3, 10.0)  # no more sensor data
        assert spin_until(executor, lambda: _zero(commands[-1]), 5.0)
    third = convert.report_from_msg(reports[2])
    assert third.plan_id == 4 and third.outcome == ExecutionReport.ABORTED
    assert "sensor timeout" in third.detail


def test_a_sensor_dropout_is_answered_at_its_timeout_not_at_the_next_tick(tmp_path):
    """At 1 Hz control the periodic tick after a dropout comes up to 1 s late; the control
    thread's watchdog stops the plan when the stream is ``sensor_timeout`` old."""
    spec = launch_nodes("mock")["executor"]
    timeout_s = 0.25
    args = ["-p", "executor:control_rate_hz:=1.0", "-p", f"executor:sensor_timeout:={timeout_s}"]
    reports, commands = [], []
    with node_with_driver(spec, tmp_path, args) as (node, driver, executor):
        plans = driver.create_publisher(DockingPlan, "plan", qos.EVENTS)
        poses = driver.create_publisher(PoseStamped, "/arm/tool_pose", qos.SENSOR)
        wrenches = driver.create_publisher(WrenchStamped, "/ft_sensor/wrench", qos.SENSOR)
        driver.create_subscription(
            ExecutionReport, "execution_report", lambda m: reports.append(time.monotonic()),
            qos.EVENTS,
        )  # fmt: skip
        driver.create_subscription(
            TwistStamped, "/arm/cmd_twist", lambda m: commands.append(m), qos.COMMAND
        )
        assert spin_until(executor, lambda: plans.get_subscription_count() > 0, 10.0)
        fed = {"last": time.monotonic()}

        def feed(done):
            poses.publish(pose_msg(0.0, 0.6, 0.3))
            wrenches.publish(WrenchStamped())
            fed["last"] = time.monotonic()
            return done()

        plans.publish(_plan_msg(1, [[0.0, 0.3], [0.0, 0.1]]))
        assert spin_until(executor, lambda: feed(lambda: node.run is not None), 10.0)
        seen = len(commands)  # stop feeding right after a periodic tick's command
        assert spin_until(executor, lambda: feed(lambda: len(commands) > seen), 5.0)
        assert spin_until(executor, lambda: bool(reports), 5.0)
    latency = reports[0] - fed["last"]
    assert timeout_s <= latency < timeout_s + 0.4, latency  # the next tick: ~1 s


def test_executor_remembers_a_bounded_number_of_plans(tmp_path):
    """Resent copies are recognised by (plan id, stamp); the memory keeps the newest
    SEEN_PLANS keys, and an evicted plan's copy is still dropped (plan-id order)."""
    spec = launch_nodes("mock")["executor"]
    with node_with_driver(spec, tmp_path) as (node, _driver, _executor):
        messages = [_plan_msg(plan_id, [[0.0, 0.3], [0.0, 0.1]]) for plan_id in range(1, 71)]
        for message in messages:
            message.decision = DockingPlan.GIVE_UP  # handled, nothing runs
            message.waypoints = message.waypoints[:1]
            node.on_plan(message)
        assert len(node.seen_plans) == executor_node.SEEN_PLANS
        newest = messages[-1]
        assert (newest.plan_id, newest.header.stamp.sec, newest.header.stamp.nanosec) in (
            node.seen_plans
        )
        with pytest.raises(convert.MessageError, match="after its plan 70"):
            node.on_plan(messages[0])


@pytest.mark.parametrize(
    ("stop", "expected"),
    [
        ("episode_ended", "episode 0 is ABORTED"),
        ("out_of_plane_force", "(3-D) above the limit"),  # 50 N along the plane normal
        ("producer_lost", PRODUCER_LOST),  # the planner stops resending the plan
    ],
)
def test_executor_stops_a_running_plan(stop, expected, tmp_path):
    spec = launch_nodes("mock")["executor"]
    reports, commands, normal_force, resend = [], [], [0.0], [True]
    timeout = ["-p", "executor:producer_timeout:=1.5"]
    with node_with_driver(spec, tmp_path, timeout) as (node, driver, executor):
        plans = driver.create_publisher(DockingPlan, "plan", qos.EVENTS)
        poses = driver.create_publisher(PoseStamped, "/arm/tool_pose", qos.SENSOR)
        wrenches = driver.create_publisher(WrenchStamped, "/ft_sensor/wrench", qos.SENSOR)
        statuses = driver.create_publisher(EpisodeStatus, "episode_status", qos.LATCHED)
        driver.create_subscription(ExecutionReport, "execution_report", reports.append, qos.EVENTS)
        driver.create_subscription(TwistStamped, "/arm/cmd_twist", commands.append, qos.COMMAND)
        publishers = (plans, poses, wrenches, statuses)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers), 10)

        plan = _plan_msg(1, [[0.0, 0.3], [0.0, 0.1]])  # episode 0

        def feed():  # live sensors and planner, so that only the tested cause stops the plan
            poses.publish(pose_msg(0.0, 0.6, 0.3))
            wrench = WrenchStamped()
            wrench.wrench.force.y = normal_force[0]  # base y = the plane's normal
            wrenches.publish(wrench)
            if resend[0]:
                plans.publish(plan)
            return node.run is not None and node.filter.ready and bool(commands)

        plans.publish(plan)
        assert spin_until(executor, lambda: feed() and not _zero(commands[-1]), 10.0)
        status = EpisodeStatus(episode=0, state=EpisodeStatus.RUNNING)
        statuses.publish(status)
        assert not spin_until(executor, lambda: feed() and reports, 0.5)  # its episode runs on
        if stop == "episode_ended":
            status.state, status.detail = EpisodeStatus.ABORTED, "no samples within 60 s"
            statuses.publish(status)
        elif stop == "producer_lost":
            resend[0] = False
        else:
            normal_force[0] = 50.0
        assert spin_until(executor, lambda: feed() is not None and reports, 10.0)
        assert spin_until(executor, lambda: _zero(commands[-1]), 5.0)
    report = convert.report_from_msg(reports[0])
    assert report.outcome == ExecutionReport.ABORTED and expected in report.detail, report.detail


def _zero(twist: TwistStamped) -> bool:
    v = twist.twist.linear
    return (v.x, v.y, v.z) == (0.0, 0.0, 0.0)


def test_inference_drops_malformed_reports_and_keeps_its_history(tmp_path):
    from tactile_dock_ros.msg import ContactHistory

    spec = launch_nodes("mock")["inference"]
    histories = []
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        reports = driver.create_publisher(ExecutionReport, "execution_report", qos.REPORTS)
        driver.create_subscription(ContactHistory, "contact_history", histories.append, qos.LATCHED)
        assert spin_until(executor, lambda: reports.get_subscription_count() > 0, 10.0)
        good = Report(
            1, ExecutionReport.NO_CONTACT,
            convert.history_from_segments([]).extend([0.0, 0.5], [0.0, 0.2], [0]),
            np.array([0.0, 0.2]), "",
        )  # fmt: skip
        msg = convert.report_to_msg(good, convert.Header(frame_id="dock_plane"))
        bad_status = convert.report_to_msg(good, convert.Header())
        bad_status.plan_id, bad_status.segments[0].status = 2, 17
        empty = convert.report_to_msg(good, convert.Header())
        empty.plan_id, empty.outcome = 3, 99
        other_episode = convert.report_to_msg(good, convert.Header())
        other_episode.plan_id, other_episode.episode = 7, 5  # late, or from a restarted planner
        for report in (bad_status, empty, other_episode, msg):
            reports.publish(report)
        assert spin_until(executor, lambda: len(node.episode_state.history) == 1, 10.0)
        assert node.handled_plans == {1} and node.episode_state.move_ids.tolist() == [1]


def test_planner_drops_malformed_samples_history_and_prior(tmp_path):
    from tactile_dock_ros.msg import ContactHistory, ShapeDistribution, ShapeSamples

    from tactile_dock_ros.core.episode import EpisodeState
    from tactile_dock_ros.core.history import History

    spec = launch_nodes("mock")["planner"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        samples = driver.create_publisher(ShapeSamples, "shape_samples", qos.LATCHED)
        history = driver.create_publisher(ContactHistory, "contact_history", qos.LATCHED)
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        publishers = (samples, history, prior)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers), 10)
        good = np.random.default_rng(0).normal(size=(3, 4, 2))
        bad_samples = convert.samples_to_msg(good, convert.Header(), "hmc", 3.0, 0)
        bad_samples.num_samples = 4  # size mismatch
        segment = convert.history_to_msg(
            EpisodeState(History([0.0, 0.5], [0.0, 0.2], [0])), convert.Header()
        )
        segment.segments[0].status = 11  # unknown status
        empty_prior = ShapeDistribution(num_vertices=0)
        samples.publish(bad_samples)
        history.publish(segment)
        prior.publish(empty_prior)
        samples_ok = convert.samples_to_msg(good, convert.Header(), "hmc", 3.0, 0)
        samples_ok.method = "after"  # a marker the planner keeps
        # A valid message sent after the bad ones arrives: the bad ones were handled (dropped).
        samples.publish(samples_ok)
        assert spin_until(executor, lambda: node.samples is not None, 10.0)
        assert node.samples[0].method == "after"
        assert len(node.episode_state.history) == 0  # the bad history was dropped
        assert node.prior is None and node.state == "IDLE"


def test_planner_needs_a_prior_and_aborts_an_episode_that_gets_no_samples(tmp_path):
    from std_srvs.srv import Trigger
    from tactile_dock_ros.msg import ShapeDistribution

    from tactile_dock_ros.core import problems

    spec = launch_nodes("mock")["planner"]
    statuses = []
    with node_with_driver(spec, tmp_path, ["-p", "planner:stage_timeout:=1.0"]) as (
        node, driver, executor,
    ):  # fmt: skip
        driver.create_subscription(EpisodeStatus, "episode_status", statuses.append, qos.LATCHED)
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        start = driver.create_client(Trigger, "start_episode")
        assert spin_until(executor, start.service_is_ready, 10.0)
        refused = start.call_async(Trigger.Request())
        assert spin_until(executor, refused.done, 10.0) and not refused.result().success
        assert "terrain_prior" in refused.result().message  # says what is missing
        prior.publish(convert.shape_to_msg(problems.get("sloper").prior, convert.Header()))
        assert spin_until(executor, lambda: node.prior is not None, 10.0)
        future = start.call_async(Trigger.Request())
        assert spin_until(executor, future.done, 10.0) and future.result().success
        again = start.call_async(Trigger.Request())
        assert spin_until(executor, again.done, 10.0) and not again.result().success  # running
        assert spin_until(
            executor, lambda: statuses and statuses[-1].state == EpisodeStatus.ABORTED, 10.0
        )
    assert "posterior samples" in statuses[-1].detail


def test_planner_gives_up_when_inference_finds_no_consistent_shape(tmp_path):
    with planner_episode(tmp_path) as ep:
        ep.pose.publish(pose_msg(0.0, 0.6, 0.45))
        empty = np.zeros((0, ep.shape.n_vertices, 2))
        ep.samples.publish(convert.samples_to_msg(empty, ep.stamp, "hmc", 0.0, 0))
        gave_up = lambda: ep.statuses and ep.statuses[-1].state == EpisodeStatus.GAVE_UP  # noqa: E731
        assert spin_until(ep.executor, gave_up, 10.0)
    assert "no shape consistent" in ep.statuses[-1].detail and not ep.plans


def test_planner_plans_with_the_slides_of_its_contact_history(tmp_path):
    from tactile_dock_ros.msg import ContactHistory
    from test_slides import LOAD, MU, level_edge, slide_probes, slope_shape

    from tactile_dock_ros.core.episode import EpisodeState
    from tactile_dock_ros.core.shape import GaussianShape

    spec = launch_nodes("mock")["planner"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        history = driver.create_publisher(ContactHistory, "contact_history", qos.LATCHED)
        assert spin_until(executor, lambda: history.get_subscription_count() > 0, 10.0)
        slope = slope_shape()
        slide = slide_probes(slope, [3, 1])  # one slide: the plan id of both rows is 4
        history.publish(convert.history_to_msg(EpisodeState(slide, [4, 4]), convert.Header()))
        assert spin_until(executor, lambda: len(node.episode_state.history) == 2, 10.0)
        assert node.episode_state.move_ids.tolist() == [4, 4]
        node.priors.receive(
            0, 0, GaussianShape(slope.ravel(), 1e-3 * np.eye(slope.size), False, MU)
        )
        node.episode_state = node.episode_state.move([0.05, 0.2])
        node.config = dataclasses.replace(node.config, load=LOAD)
        up = np.array([0.0, 1e-3])
        result = node.plan(np.stack([slope, slope + up, slope - up, level_edge(slope, 2)]))
        assert result.rejected == 1 and result.decision == "give_up", result.reason
