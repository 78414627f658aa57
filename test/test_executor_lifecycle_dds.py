"""The executor as a lifecycle node.

In-process: configure fails on an invalid parameter (and creates nothing), a configured but
inactive executor refuses plans. Over DDS (``tools.safety.mock_floor``: executor and
mock_hardware as processes, the probe plays the planner and calls the executor's
``change_state`` service): deactivate stops a moving arm within 2 control periods and aborts the
plan, a plan sent while inactive does not move the arm, activate runs plans again.
"""

import threading

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import TwistStamped
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState
from node_helpers import launch_nodes, node_with_driver
from ros_helpers import spin_until
from tactile_dock_ros.msg import DockingPlan, EpisodeStatus, ExecutionReport

from tactile_dock_ros.execution.types import PlanCommand
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.nodes.executor_node import FAILURE, INACTIVE, SUCCESS
from tactile_dock_ros.tools import safety

pytestmark = pytest.mark.dds
EPISODE, NONCE = 7, 0x11FE_C7C1E
FAST_DIAGNOSTICS = {"executor": {"diagnostics_period": 0.2}}
LOAD_SLACK_S = 0.15  # as test_safety_dds: scheduling allowance on a shared 2-core machine
MANUAL = {"executor_autostart": "false"}  # the launch argument


def _state(node) -> int:
    return node._state_machine.current_state[0]


def test_configure_fails_on_an_invalid_parameter_and_creates_nothing(tmp_path):
    spec = launch_nodes("mock", **MANUAL)["executor"]
    bad = ["-p", "executor:max_speed:=5.0"]
    with node_with_driver(spec, tmp_path, bad) as (node, _driver, _executor):
        assert _state(node) == State.PRIMARY_STATE_UNCONFIGURED
        publishers = {p.topic_name for p in node.publishers}
        assert node.trigger_configure() == FAILURE
        assert _state(node) == State.PRIMARY_STATE_UNCONFIGURED
        assert "max_speed" in node.config_error and node.cmd_pub is None
        assert {p.topic_name for p in node.publishers} == publishers  # no cmd_twist
        assert node.trigger_configure() == FAILURE  # the same answer again


def _plan_msg(driver, plan_id: int):
    command = PlanCommand(
        plan_id, True, np.array([[0.0, 0.3], [0.0, 0.1]]), np.array([0.0, -1.0]), 3.0, 0.1,
        False, 0.5, 0.5, 0, "test", episode=EPISODE, nonce=NONCE,
    )  # fmt: skip
    stamp = driver.get_clock().now().to_msg()
    return convert.plan_to_msg(command, convert.Header(stamp=stamp, frame_id="dock_plane"))


def test_an_inactive_executor_refuses_plans_and_commands_nothing(tmp_path):
    spec = launch_nodes("mock", **MANUAL)["executor"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        assert node.trigger_configure() == SUCCESS
        assert _state(node) == State.PRIMARY_STATE_INACTIVE
        reports, commands = [], []
        driver.create_subscription(ExecutionReport, "/execution_report", reports.append, 10)
        driver.create_subscription(TwistStamped, "/arm/cmd_twist", commands.append, qos.COMMAND)
        plans = driver.create_publisher(DockingPlan, "/plan", qos.EVENTS)
        status = driver.create_publisher(EpisodeStatus, "/episode_status", qos.LATCHED)
        header = convert.Header(stamp=driver.get_clock().now().to_msg())
        status.publish(convert.episode_status_to_msg(header, "RUNNING", EPISODE, "", 0, [], NONCE))
        assert spin_until(executor, lambda: node.gate.current == EPISODE, 10.0)
        assert spin_until(executor, lambda: plans.get_subscription_count() > 0, 10.0)
        plans.publish(_plan_msg(driver, 1))
        assert spin_until(executor, lambda: reports, 10.0)
        assert reports[0].detail == INACTIVE and node.last_plan == (0, 0)  # no state changed
        assert not any(np.linalg.norm([c.twist.linear.x, c.twist.linear.y]) for c in commands)
        assert node.trigger_activate() == SUCCESS
        plans.publish(_plan_msg(driver, 2))  # the next plan is accepted (waits for sensors)
        assert spin_until(executor, lambda: node.pending is not None, 10.0)
        assert node.trigger_deactivate() == SUCCESS
        assert node.pending is None
        assert spin_until(executor, lambda: len(reports) == 2, 10.0)
        assert "stopped before starting: executor deactivated" in reports[-1].detail


def _change_state(probe, client, transition: int) -> bool:
    future = client.call_async(ChangeState.Request(transition=Transition(id=transition)))
    return probe.spin_until(future.done, 10.0) and future.result().success


def _moving(commands) -> bool:
    return any(np.linalg.norm(v) > 0 for _, v, _ in commands)


def test_deactivate_stops_the_arm_and_activate_runs_plans_again(tmp_path):
    with safety.mock_floor(tmp_path, FAST_DIAGNOSTICS) as (probe, env, _):
        client = probe.create_client(ChangeState, "/executor/change_state")
        assert probe.spin_until(client.service_is_ready, 10.0)
        probe.status(EPISODE, "RUNNING", NONCE)
        assert probe.wait_episode(f"{EPISODE} RUNNING")
        tool = probe.tool(env)
        n = len(probe.rec.commands)
        first = probe.plan(safety.traverse(tool, -0.5 if tool[0] > 0 else 0.5), speed=0.2)
        assert probe.spin_until(lambda: _moving(probe.rec.commands[n:]), 15.0)
        probe.spin_until(lambda: False, 0.3)
        t_transition = probe.get_clock().now().nanoseconds * 1e-9
        assert _change_state(probe, client, Transition.TRANSITION_DEACTIVATE)
        report = probe.report(first, 10.0)
        assert report is not None and report.outcome_name == "ABORTED", report
        assert "deactivated" in report.detail and len(report.history) == 0, report
        probe.spin_until(lambda: False, 0.3)
        after = [
            (t, float(np.linalg.norm(v))) for t, v, _ in probe.rec.commands if t > t_transition
        ]
        zeros = [t for t, speed in after if speed == 0.0]
        assert zeros, after[:5]
        assert zeros[0] - t_transition <= 2 * env.control_period + LOAD_SLACK_S, zeros[0]
        assert not any(speed > 0 for t, speed in after if t >= zeros[0]), after

        t_inactive = probe.get_clock().now().nanoseconds * 1e-9
        refused = probe.report(probe.plan(safety.traverse(probe.tool(env), tool[0])), 10.0)
        assert refused is not None and refused.detail == INACTIVE, refused
        probe.spin_until(lambda: False, 0.5)
        assert not any(np.linalg.norm(v) > 0 for t, v, _ in probe.rec.commands if t > t_inactive)

        assert _change_state(probe, client, Transition.TRANSITION_ACTIVATE)
        n = len(probe.rec.commands)
        third = probe.plan(safety.traverse(probe.tool(env), tool[0]))
        assert probe.spin_until(lambda: _moving(probe.rec.commands[n:]), 15.0)
        done = probe.report(third, 30.0)
        assert done is not None and done.outcome_name == "NO_CONTACT", done


def test_a_destroyed_executor_leaves_the_ros_graph(tmp_path):
    """rclpy's lifecycle state machine holds the node handle: without destroying it with the
    node, a destroyed executor stayed in the graph until collected (a second 'executor' that
    graph queries by name could find first)."""
    from rclpy.context import Context
    from ros_helpers import ros_node

    from tactile_dock_ros.nodes.executor_node import ExecutorNode

    with ros_node("graph_probe") as (probe, executor):
        context = Context()
        rclpy.init(context=context)
        node = ExecutorNode(context=context)
        names = probe.get_node_names_and_namespaces
        assert spin_until(executor, lambda: ("executor", "/") in names(), 10.0)
        node.destroy_node()
        rclpy.shutdown(context=context)
        assert spin_until(executor, lambda: ("executor", "/") not in names(), 10.0)
        del node  # (kept alive until here: collection must not be what removes it)


class _TickFault(RuntimeError):
    pass


def test_an_exception_in_the_control_loop_stops_the_arm_and_ends_the_spin(tmp_path):
    """The control loop runs on its own thread; an exception there commands zero and is raised
    in the thread that spins the node (as a callback's exception: ``common.run`` exits)."""
    spec = launch_nodes("mock", **MANUAL)["executor"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        commands = []
        driver.create_subscription(TwistStamped, "/arm/cmd_twist", commands.append, qos.COMMAND)
        assert node.trigger_configure() == SUCCESS
        assert spin_until(executor, lambda: node.cmd_pub.get_subscription_count() > 0, 10.0)
        ticks = []

        def failing_tick():
            ticks.append(threading.get_ident())
            if len(ticks) == 3:
                raise _TickFault("tick failed")

        node.on_tick = failing_tick  # the control thread calls what is set at activate
        assert node.trigger_activate() == SUCCESS
        with pytest.raises(_TickFault):
            spin_until(executor, lambda: False, 10.0)
        assert len(ticks) == 3 and set(ticks) != {threading.get_ident()}  # not this thread
        assert spin_until(executor, lambda: commands, 5.0)
        assert commands[-1].twist.linear.x == commands[-1].twist.linear.y == 0.0
        assert not node.active
