"""System test: the five nodes of the mock launch file as separate processes, over DDS.

The executables, parameters and remappings come from launch/tactile_dock.launch.xml
(profile:=mock), so this runs what `ros2 launch` would. A seeded feasible terrain docks within
the planner's cycle budget; an infeasible one ends GAVE_UP, and its recorded bag replays offline
to the very plans the planner published; the executor's commands stay within its speed limit and
the tool within its workspace box throughout.
"""

import json

import numpy as np
import pytest
import rclpy
import yaml
from conftest import REPO_ROOT
from geometry_msgs.msg import PoseStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from tactile_dock_ros.core import problems
from tactile_dock_ros.execution.types import PlaneFrame
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.tools import bag, bringup, episode, replay

pytestmark = pytest.mark.dds
CONFIG = yaml.safe_load((REPO_ROOT / "config" / "mock.yaml").read_text())
SHARED = CONFIG["/**"]["ros__parameters"]
EXECUTOR = CONFIG["executor"]["ros__parameters"]
MAX_CYCLES = CONFIG["planner"]["ros__parameters"]["max_cycles"]
# Sloper draws (seeded) whose feasibility core.simulate.feasible decides; checked below.
FEASIBLE_SEED, INFEASIBLE_SEED = 0, 5


def _episode(tmp_path, seed: int):
    arguments = {
        "profile": "mock",
        "problem": "sloper",
        "seed": str(seed),
        "prior_source": "problem",
    }
    poses = []
    context = Context()
    rclpy.init(context=context)
    client = episode.EpisodeClient(context=context)
    client.create_subscription(PoseStamped, "/arm/tool_pose", poses.append, qos.SENSOR)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(client)
    try:
        with bringup.running(arguments, tmp_path):
            record = client.run(executor, timeout_s=240.0, progress=print)
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown(context=context)
    plane = PlaneFrame(SHARED["plane_origin"], SHARED["plane_x_axis"], SHARED["plane_y_axis"])
    tool = np.array([convert.pose_position(p, plane) for p in poses])
    return record, tool


def _logs(tmp_path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in tmp_path.glob("*.log"))


def _assert_within_limits(record, tool):
    assert record.command_speeds, "no command reached the arm"
    assert max(record.command_speeds) <= EXECUTOR["max_speed"] + 1e-9
    margin = 0.005  # metres: pose noise and the stop after the last command
    assert np.all(tool >= np.array(EXECUTOR["workspace_min"]) - margin)
    assert np.all(tool <= np.array(EXECUTOR["workspace_max"]) + margin)


def test_seeds_are_what_the_test_claims():
    from tactile_dock_ros.core.simulate import feasible

    sloper = problems.get("sloper")
    truth = {s: sloper.sample_ground_truth(np.random.default_rng(s)) for s in (0, 5)}
    assert feasible(sloper, truth[FEASIBLE_SEED]) and not feasible(sloper, truth[INFEASIBLE_SEED])


def test_feasible_terrain_docks_within_the_cycle_budget(tmp_path):
    record, tool = _episode(tmp_path, FEASIBLE_SEED)
    assert record.state == "DOCKED", _logs(tmp_path)
    assert 1 <= len(record.plans) <= MAX_CYCLES
    assert len(record.reports) == len(record.plans)
    _assert_within_limits(record, tool)


def test_infeasible_terrain_ends_gave_up(tmp_path):
    record, tool = _episode(tmp_path, INFEASIBLE_SEED)
    assert record.state == "GAVE_UP", _logs(tmp_path)
    assert all(r.outcome != r.DOCKED for r in record.reports)
    _assert_within_limits(record, tool)
    # The episode's bag replays offline to exactly the plans the planner node published; it
    # offers each topic with the QoS its publisher offered (latched ones latched).
    bag.write(tmp_path / "bag", record.messages, offered=record.offered_qos)
    metadata = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    offered = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
        for t in metadata["rosbag2_bagfile_information"]["topics_with_message_count"]
    }
    for topic, profile in bag.QOS.items():
        assert [p["durability"] for p in offered[topic]] == [profile.durability.name.lower()]
    out = tmp_path / "replay.json"
    config = REPO_ROOT / "config" / "mock.yaml"
    assert replay.main([str(tmp_path / "bag"), "--config", str(config), "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert len(rows) == len(record.plans) and all(r["same"] for r in rows), rows
