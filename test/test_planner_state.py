"""The planner node resumes an episode from its journal (in-process, over DDS), or refuses to.

A journal as a killed planner leaves it: the episode started, a DOCK plan published, no report
yet. A planner started on it republishes the episode id, reports RUNNING with the cycle, and
resends the very plan (same id and stamp: the executor sees copies, not a new plan) and keeps
the overrides of the episode's dock goal; an old journal (older than resume_timeout) ends the
episode ABORTED instead.
"""

import base64
import time

import numpy as np
import pytest
from node_helpers import launch_nodes, node_with_driver
from rclpy.serialization import serialize_message
from ros_helpers import spin_until
from std_msgs.msg import UInt32
from tactile_dock_ros.msg import DockingPlan, EpisodeCycle, EpisodeStatus

from tactile_dock_ros.execution.types import PlanCommand
from tactile_dock_ros.nodes import convert, journal, qos

pytestmark = pytest.mark.dds
EPISODE = 77


def _journal(directory, age_s: float, settings: dict | None = None) -> DockingPlan:
    """A killed planner's journal; ``settings``: its dock goal's (None: a journal written
    before goals had any)."""
    command = PlanCommand(
        1, True, np.array([[0.0, 0.3], [0.0, 0.1]]), np.array([0.0, -1.0]), 3.0, 0.1, False,
        0.4, 0.4, 2, "", np.array([0.0, 0.1]), EPISODE, 0,
    )  # fmt: skip
    header = convert.Header(frame_id="dock_plane")
    header.stamp.sec, header.stamp.nanosec = 1234, 5678
    plan = convert.plan_to_msg(command, header)
    wall = time.time() - age_s
    events = [
        {"event": "start", "episode": EPISODE, "start_ns": 10**9, "wall_time": wall}
        | ({} if settings is None else {"settings": settings}),
        {
            "event": "plan", "history_length": 0, "p_dock": 0.4, "inference_s": 0.1,
            "planning_s": 0.01, "plan_stamp": 1234.0, "dock": True, "target": [0.0, 0.1],
            "msg": base64.b64encode(serialize_message(plan)).decode(), "wall_time": wall,
        },
    ]  # fmt: skip
    journal.Journal(directory / "planner.jsonl").reset(events)
    return plan


def _planner(tmp_path):
    spec = launch_nodes("mock", state_directory=str(tmp_path / "state"))["planner"]
    return node_with_driver(spec, tmp_path)


def test_a_restarted_planner_resumes_the_running_episode(tmp_path):
    plan = _journal(tmp_path / "state", age_s=1.0)
    plans, episodes, statuses = [], [], []
    with _planner(tmp_path) as (node, driver, executor):
        driver.create_subscription(DockingPlan, "plan", plans.append, qos.EVENTS)
        driver.create_subscription(UInt32, "episode", episodes.append, qos.LATCHED)
        driver.create_subscription(EpisodeStatus, "episode_status", statuses.append, qos.LATCHED)
        assert spin_until(executor, lambda: len(plans) >= 2 and episodes and statuses, 10.0)
        assert episodes[-1].data == EPISODE and node.awaiting_plan == 1
        status = statuses[-1]
        assert (status.episode, status.state) == (EPISODE, EpisodeStatus.RUNNING)
        assert status.detail == "resumed after a restart" and len(status.cycles) == 1
        assert status.cycles[0].outcome == EpisodeCycle.PENDING  # its plan is executing
        assert all(p == plan for p in plans)  # copies of the journaled plan, its stamp included
        np.testing.assert_array_equal(node.episode_state.targets, [[0.0, 0.1]])
        assert node.settings["max_cycles"] == node.p.max_cycles  # no settings: the parameters


def test_a_resumed_episode_keeps_its_goal_overrides(tmp_path):
    settings = {"max_cycles": 3, "give_up_threshold": 0.05, "compliant": True}
    _journal(tmp_path / "state", age_s=1.0, settings=settings)
    with _planner(tmp_path) as (node, _, _):
        assert node.state == "RUNNING"
        assert {key: node.settings[key] for key in settings} == settings
        assert node.config.give_up_threshold == 0.05 and node.config.compliant


def test_an_old_journal_is_not_resumed(tmp_path):
    _journal(tmp_path / "state", age_s=1000.0)  # resume_timeout: 120 s
    statuses, plans = [], []
    with _planner(tmp_path) as (_, driver, executor):
        driver.create_subscription(EpisodeStatus, "episode_status", statuses.append, qos.LATCHED)
        driver.create_subscription(DockingPlan, "plan", plans.append, qos.EVENTS)
        assert spin_until(executor, lambda: statuses, 10.0)
        assert not spin_until(executor, lambda: plans, 1.0)  # nothing resent
    assert statuses[-1].state == EpisodeStatus.ABORTED, statuses[-1]
    assert statuses[-1].detail.startswith("not resumed"), statuses[-1].detail
    assert journal.read(tmp_path / "state" / "planner.jsonl")[-1]["state"] == "ABORTED"
