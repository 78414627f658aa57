"""Docking on a chosen hold, over DDS: the planner plans the episode on the prior of the hold
its goal names (exactly core.planner.plan on that prior's samples), an unknown hold id is
rejected changing nothing, and inference samples on the hold the episode status names. A
planner or inference started after several captures receives every kept hold
(``qos.priors``), the latest last."""

import threading
from functools import partial

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from node_helpers import launch_nodes, node_with_driver, planner_driver, pose_msg
from rclpy.action import ActionClient
from ros_helpers import ros_node, send_goal, spin_until
from std_msgs.msg import UInt32
from tactile_dock_ros.action import Dock
from tactile_dock_ros.msg import (
    EpisodeStatus,
    ShapeDistribution,
    ShapeSamples,
)

from tactile_dock_ros.core import planner, problems, sampling
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.history import History
from tactile_dock_ros.nodes import convert, inference_node, qos

pytestmark = pytest.mark.dds

PLANE = convert.Header(frame_id="dock_plane")
HOLDS = {1: problems.get("sloper").prior, 2: problems.get("notch").prior}  # 12, 24 vertices
CAPTURES = [*HOLDS.values(), problems.get("three_ledges").prior]  # 82 vertices


def _publish_holds(publisher, executor, node) -> None:
    """Hold 1, then hold 2 (the latest) once hold 1 arrived (``publisher`` keeps the last 1)."""
    for hold_id, prior in HOLDS.items():
        publisher.publish(convert.shape_to_msg(prior, PLANE, hold_id))
        assert spin_until(executor, lambda h=hold_id: h in node.priors.holds.ids(), 10.0)


def _draws(hold_id: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return sampling.sample_posterior(HOLDS[hold_id], History(), 40, rng).vertices


def _state(node) -> tuple:
    return (node.state, node.episode, node.hold_id, node.nonce, node.settings, len(node.cycles),
            node.goal, node.episode_start)  # fmt: skip


def test_a_goal_docks_on_the_hold_it_names_and_an_unknown_hold_is_rejected(tmp_path):
    spec = launch_nodes("mock")["planner"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        ends = planner_driver(driver)
        statuses, plans, prior, history, samples, pose = vars(ends).values()
        client = ActionClient(driver, Dock, "/dock")
        send = partial(send_goal, executor, client)

        try:
            assert spin_until(
                executor,
                lambda: client.server_is_ready() and ends.matched(),
                10.0,
            )
            _publish_holds(prior, executor, node)
            pose.publish(pose_msg(0.02, 0.0, 0.3))
            assert spin_until(
                executor,
                lambda: (
                    node.priors.holds.ids() == [1, 2]
                    and node.episode_state.tool is not None
                    and statuses
                    and statuses[-1].hold_id == 2
                ),
                10.0,
            )
            assert statuses[-1].prior_vertices == 24  # idle: the latest hold, what {} docks on

            before = _state(node)
            assert not send(Dock.Goal(hold_id=3)).accepted  # never captured
            assert _state(node) == before

            handle = send(Dock.Goal(hold_id=1))  # the older hold
            assert handle.accepted and node.state == "RUNNING" and node.hold_id == 1
            assert spin_until(
                executor,
                lambda: statuses[-1].state == EpisodeStatus.RUNNING and statuses[-1].hold_id == 1,
                10.0,
            )
            assert statuses[-1].prior_vertices == 12
            stamp = convert.Header(stamp=driver.get_clock().now().to_msg(), frame_id="dock_plane")
            history.publish(convert.history_to_msg(EpisodeState(), stamp))
            tool = node.episode_state.tool
            # samples of the latest hold (inference not switched yet) are not planned on
            other = convert.samples_to_msg(_draws(2), stamp, "hmc", 5.0, 0, hold_id=2)
            samples.publish(other)
            drawn = _draws(1)
            samples.publish(convert.samples_to_msg(drawn, stamp, "hmc", 5.0, 0, hold_id=1))
            assert spin_until(executor, lambda: plans, 20.0), "no plan"
            expected = planner.plan(drawn, HOLDS[1], EpisodeState(tool=tool), node.config)
            plan = convert.plan_from_msg(plans[0])
            assert plan.p_dock == expected.p_dock and plan.reason == expected.reason
            assert plan.dock == (expected.decision == "dock")
            if plan.dock:
                assert plan.target_edge == expected.target_edge
                assert np.array_equal(plan.waypoints, np.asarray(expected.path).reshape(-1, 2))

            # a capture while the episode runs does not change its prior
            prior.publish(convert.shape_to_msg(problems.get("three_ledges").prior, PLANE, 3))
            assert spin_until(executor, lambda: node.priors.holds.ids() == [1, 2, 3], 10.0)
            assert node.prior.n_vertices == 12

            result = handle.get_result_async()
            handle.cancel_goal_async()
            assert spin_until(executor, result.done, 10.0)
            assert result.result().status == GoalStatus.STATUS_CANCELED
            assert result.result().result.hold_id == 1
        finally:
            client.destroy()


def test_inference_samples_on_the_hold_the_episode_status_names(tmp_path):
    spec = launch_nodes("mock")["inference"]
    received = []
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        driver.create_subscription(ShapeSamples, "shape_samples", received.append, qos.LATCHED)
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        episode = driver.create_publisher(UInt32, "episode", qos.LATCHED)
        status = driver.create_publisher(EpisodeStatus, "episode_status", qos.LATCHED)
        publishers = (prior, episode, status)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers), 10)
        _publish_holds(prior, executor, node)
        assert spin_until(executor, lambda: node.priors.holds.ids() == [1, 2], 10.0)
        status.publish(convert.episode_status_to_msg(PLANE, "RUNNING", 7, "", 12, [], 5, 1))
        episode.publish(UInt32(data=7))
        assert spin_until(executor, lambda: any(m.hold_id == 1 for m in received), 60.0)
        first = next(m for m in received if m.hold_id == 1)
        assert first.num_vertices == 12 and first.history_length == 0
        assert all(m.num_vertices == (12 if m.hold_id == 1 else 24) for m in received)


def _captured(node, count: int) -> object:
    """A perception-like publisher on ``node`` that has published holds 1..``count`` (sloper,
    notch, three_ledges, sloper, ...), as perception does: ``qos.priors`` of ``max_holds`` 8."""
    publisher = node.create_publisher(ShapeDistribution, "terrain_prior", qos.priors(8))
    for hold_id in range(1, count + 1):
        publisher.publish(convert.shape_to_msg(CAPTURES[(hold_id - 1) % 3], PLANE, hold_id))
    return publisher


def test_a_planner_started_after_three_captures_docks_on_the_first(tmp_path):
    """The planner starts after holds 1, 2, 3 were published: it keeps all three, 3 is the
    latest (what its idle status names), and a goal for hold 1 plans on hold 1's prior."""
    spec = launch_nodes("mock")["planner"]
    with ros_node("perception") as (perception, _):
        captured = _captured(perception, 3)
        with node_with_driver(spec, tmp_path) as (node, driver, executor):
            ends = planner_driver(driver, prior=captured)
            statuses, plans, _, history, samples, pose = vars(ends).values()
            client = ActionClient(driver, Dock, "/dock")
            try:
                assert spin_until(
                    executor, lambda: client.server_is_ready() and ends.matched(), 10.0
                )
                pose.publish(pose_msg(0.02, 0.0, 0.3))
                assert spin_until(
                    executor,
                    lambda: (
                        node.priors.holds.ids() == [1, 2, 3]
                        and node.episode_state.tool is not None
                        and statuses
                        and statuses[-1].hold_id == 3
                    ),
                    10.0,
                ), f"holds received: {node.priors.holds.ids()}"
                assert node.priors.latest.hold_id == 3 and node.prior.n_vertices == 82

                handle = send_goal(executor, client, Dock.Goal(hold_id=1))
                assert handle.accepted and node.hold_id == 1 and node.prior.n_vertices == 12
                stamp = convert.Header(
                    stamp=driver.get_clock().now().to_msg(), frame_id="dock_plane"
                )
                history.publish(convert.history_to_msg(EpisodeState(), stamp))
                drawn = _draws(1)
                samples.publish(convert.samples_to_msg(drawn, stamp, "hmc", 5.0, 0, hold_id=1))
                assert spin_until(executor, lambda: plans, 20.0), "no plan"
                tool = node.episode_state.tool
                expected = planner.plan(drawn, HOLDS[1], EpisodeState(tool=tool), node.config)
                plan = convert.plan_from_msg(plans[0])
                assert plan.p_dock == expected.p_dock and plan.reason == expected.reason

                result = handle.get_result_async()
                handle.cancel_goal_async()
                assert spin_until(executor, result.done, 10.0)
                assert result.result().result.hold_id == 1
            finally:
                client.destroy()


def test_inference_started_after_eight_captures_samples_only_the_latest(tmp_path, monkeypatch):
    """Inference starts after holds 1..8 and an episode id (no status: it samples on the latest
    prior). Its first sampling call blocks until all eight arrived (a sampling slower than the
    replay): that call's result is dropped unless it was hold 8's, one more samples hold 8, and
    only hold 8's samples are published."""
    release, held = threading.Event(), []  # held: the prior of each sampling call

    def blocking_sampler(prior, *args, **kwargs):
        held.append(prior)
        if len(held) == 1:
            assert release.wait(20.0), "the test never released the sampler"
        return real_sampler(prior, *args, **kwargs)

    real_sampler = sampling.sample_posterior
    monkeypatch.setattr(sampling, "sample_posterior", blocking_sampler)
    spec = launch_nodes("mock")["inference"]
    threads = partial(inference_node.DrainingExecutor, num_threads=3)  # as its main runs it
    received = []
    with ros_node("perception") as (perception, _):
        _captured(perception, 8)
        episode = perception.create_publisher(UInt32, "episode", qos.LATCHED)
        episode.publish(UInt32(data=7))
        with node_with_driver(spec, tmp_path, [], threads) as (node, driver, executor):
            driver.create_subscription(ShapeSamples, "shape_samples", received.append, qos.LATCHED)
            assert spin_until(executor, lambda: node.priors.holds.ids() == [*range(1, 9)], 10.0)
            release.set()
            assert spin_until(executor, lambda: received, 60.0), "no samples"
            latest = node.priors.latest
            assert latest.hold_id == 8
            assert spin_until(executor, lambda: held[-1] is latest.prior, 30.0)
            assert all(m.hold_id == 8 and m.num_vertices == 24 for m in received)
            assert len(held) <= 2, [p.n_vertices for p in held]
