"""The mock arm enforces its own speed limit and box whatever it is commanded, as a real driver
does (``mock_physics.limit_command``; in-process node over DDS for the wiring)."""

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from node_helpers import launch_nodes, node_with_driver
from rclpy.time import Time
from ros_helpers import spin_until

from tactile_dock_ros.execution.mock_physics import limit_command
from tactile_dock_ros.nodes import convert, qos

BOX = ([-1.0, -1.0], [1.0, 1.0])
DT = 0.005


def test_an_over_speed_command_is_scaled_down_along_its_direction():
    velocity, reasons = limit_command([0.6, -0.8], [0.0, 0.0], DT, 0.25, *BOX)
    np.testing.assert_allclose(velocity, [0.15, -0.2])
    assert reasons == ["speed 1 m/s above 0.25"]
    velocity, reasons = limit_command([0.1, 0.0], [0.0, 0.0], DT, 0.25, *BOX)
    np.testing.assert_array_equal(velocity, [0.1, 0.0])
    assert reasons == []


def test_a_command_leaving_the_box_stops_at_its_edge_and_may_come_back():
    # 0.2 mm below the top: this step may go 0.2 mm up (0.04 m/s), x untouched
    velocity, reasons = limit_command([0.1, 0.2], [0.0, 0.9998], DT, 0.25, *BOX)
    np.testing.assert_allclose(velocity, [0.1, 0.04])
    assert reasons and "leaving the workspace box" in reasons[0]
    outside = [1.5, 0.0]  # (started outside): further out is zeroed, back in is kept
    np.testing.assert_array_equal(limit_command([0.1, 0.1], outside, DT, 0.25, *BOX)[0], [0, 0.1])
    np.testing.assert_array_equal(limit_command([-0.1, 0.0], outside, DT, 0.25, *BOX)[0], [-0.1, 0])


@pytest.mark.dds
def test_the_mock_arm_clamps_an_over_speed_command_and_stops_at_its_box(tmp_path):
    spec = launch_nodes("mock")["mock_hardware"]
    top = 0.55  # plane y; the sloper tool starts at (0, 0.45) in free space
    args = [
        "-p",
        "mock_hardware:pose_noise:=0.0",
        "-p",
        f"mock_hardware:workspace_max:=[1.0, {top}]",
    ]
    poses = []
    with node_with_driver(spec, tmp_path, args) as (node, driver, executor):
        command = driver.create_publisher(TwistStamped, "/arm/cmd_twist", qos.COMMAND)
        driver.create_subscription(PoseStamped, "/arm/tool_pose", poses.append, qos.SENSOR)
        assert spin_until(executor, lambda: command.get_subscription_count() > 0 and poses, 10.0)
        up = np.array([0.0, 0.0, 1.0])  # 1 m/s along the base z = plane y

        def send():
            header = convert.Header(stamp=driver.get_clock().now().to_msg(), frame_id="base_link")
            command.publish(convert.twist_to_msg(up, header))

        driver.create_timer(0.01, send)
        n0 = len(poses)
        assert spin_until(executor, lambda: node.sim.tool[1] >= top - 1e-9, 10.0)
        # poses stamped from here on were published after the arm reached the box; ones stamped
        # before may still arrive after it (a busy machine delays their callbacks)
        edge_ns = node.get_clock().now().nanoseconds

        def pushing_on():
            return [p for p in poses if Time.from_msg(p.header.stamp).nanoseconds > edge_ns]

        assert spin_until(executor, lambda: len(pushing_on()) >= 40, 10.0)
    heights = np.array([p.pose.position.z for p in poses[n0:]])
    at_edge = np.array([p.pose.position.z for p in pushing_on()])
    steps = np.diff(heights)
    moving = steps[steps > 1e-9]
    # each tick moves at most max_speed * dt (0.3 m/s: 1.5 mm), not 1 m/s (5 mm)
    assert moving.size >= 10 and moving.max() <= node.p.max_speed * node.dt * (1 + 1e-9), moving
    assert heights.max() <= top + 1e-9 and np.all(at_edge >= top - 1e-9)
