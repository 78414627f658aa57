"""The planner's dock action in-process, a driver node as its client: refused goals change no
state, one goal at a time, the overrides reach the episode, cancel ends it CANCELED."""

import math
from functools import partial

import pytest
from action_msgs.msg import GoalStatus
from node_helpers import launch_nodes, node_with_driver
from rclpy.action import ActionClient
from ros_helpers import send_goal, spin_until
from tactile_dock_ros.action import Dock
from tactile_dock_ros.msg import EpisodeStatus, ShapeDistribution

from tactile_dock_ros.core import problems
from tactile_dock_ros.nodes import convert, qos

pytestmark = pytest.mark.dds

OUT_OF_RANGE = [
    Dock.Goal(hold_id=2),  # no such hold received
    Dock.Goal(max_cycles=1001),
    Dock.Goal(give_up_threshold=1.5),
    Dock.Goal(give_up_threshold=-0.1),
    Dock.Goal(give_up_threshold=math.nan),
    Dock.Goal(compliant=3),
]


def _state(node) -> tuple:
    """What a refused goal must leave as it was."""
    return (node.state, node.episode, node.nonce, node.settings, node.config, len(node.cycles),
            node.goal, node.episode_start)  # fmt: skip


def test_goals_are_checked_one_runs_at_a_time_and_cancel_ends_it_canceled(tmp_path):
    spec = launch_nodes("mock")["planner"]
    statuses = []
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        driver.create_subscription(EpisodeStatus, "episode_status", statuses.append, qos.LATCHED)
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        client = ActionClient(driver, Dock, "/dock")
        send = partial(send_goal, executor, client)

        try:
            assert spin_until(
                executor,
                lambda: client.server_is_ready() and prior.get_subscription_count() and statuses,
                10.0,
            )
            before = _state(node)
            assert not send(Dock.Goal()).accepted  # no terrain_prior yet
            assert _state(node) == before
            prior.publish(convert.shape_to_msg(problems.get("sloper").prior, convert.Header()))
            assert spin_until(executor, lambda: node.prior is not None, 10.0)
            before = _state(node)
            for goal in OUT_OF_RANGE:
                assert not send(goal).accepted, goal
                assert _state(node) == before, goal

            goal = Dock.Goal(max_cycles=3, give_up_threshold=0.01, compliant=Dock.Goal.COMPLIANT)
            handle = send(goal)
            assert handle.accepted and node.state == "RUNNING"
            settings = {"max_cycles": 3, "give_up_threshold": 0.01, "compliant": True}
            assert node.settings == settings | {"hold_id": 0}  # a prior that is no captured hold
            assert node.config.compliant and node.config.give_up_threshold == 0.01
            running = _state(node)
            assert not send(Dock.Goal()).accepted  # a second goal while one runs
            assert _state(node) == running

            result = handle.get_result_async()
            handle.cancel_goal_async()
            assert spin_until(executor, result.done, 10.0)
            assert result.result().status == GoalStatus.STATUS_CANCELED
            outcome = result.result().result
            assert outcome.outcome == EpisodeStatus.CANCELED and outcome.episode == node.episode
            assert outcome.reason and node.state == "CANCELED" and node.goal is None
            assert spin_until(
                executor,
                lambda: (
                    statuses[-1].state == EpisodeStatus.CANCELED
                    and statuses[-1].episode == node.episode
                ),
                10.0,
            )

            # The next episode runs on the node's parameters again.
            handle = send(Dock.Goal())
            assert handle.accepted and node.settings["max_cycles"] == node.p.max_cycles
            assert node.config.compliant == node.p.compliant
        finally:
            client.destroy()
