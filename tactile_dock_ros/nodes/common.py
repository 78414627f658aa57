"""Glue shared by every node: plane-frame parameters, stamped headers, guarded callbacks, main."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import Header

from tactile_dock_ros.nodes.convert import MessageError, PlaneFrame
from tactile_dock_ros.nodes.params import Param

# The docking plane in the arm base frame (tf2 is not used; docs/nodes.md, "Running it").
PLANE_FRAME_ID = Param("plane_frame_id", "dock_plane", "frame id stamped on plane-frame messages")
PLANE_TABLE = [
    PLANE_FRAME_ID,
    Param("base_frame_id", "base_link", "arm base frame of poses, wrenches and commands"),
    Param("plane_origin", [0.0, 0.0, 0.0], "plane origin in the base frame", "m", length=3),
    Param("plane_x_axis", [1.0, 0.0, 0.0], "plane x axis in the base frame", "unit", length=3),
    Param("plane_y_axis", [0.0, 0.0, 1.0], "plane y axis (up) in the base frame", "unit", length=3),
]


def plane_frame(values) -> PlaneFrame:
    return PlaneFrame(values.plane_origin, values.plane_x_axis, values.plane_y_axis)


def header(node: Node, frame_id: str) -> Header:
    """A header stamped with the node clock (ROS time when use_sim_time is set)."""
    return Header(stamp=node.get_clock().now().to_msg(), frame_id=frame_id)


def now_seconds(node: Node) -> float:
    """The node clock in seconds (ROS time when use_sim_time is set)."""
    return node.get_clock().now().nanoseconds * 1e-9


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time -> seconds."""
    return stamp.sec + 1e-9 * stamp.nanosec


def guarded(node: Node, what: str, callback: Callable) -> Callable:
    """Wrap a subscription callback: a MessageError is logged and the message dropped."""

    def wrapped(msg) -> None:
        try:
            callback(msg)
        except MessageError as err:
            node.get_logger().error(f"dropped malformed {what}: {err}")

    return wrapped


class Stopwatch:
    """Wall-clock seconds of a block: ``with Stopwatch() as sw: ...; sw.seconds``."""

    def __enter__(self) -> Stopwatch:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = time.perf_counter() - self._t0


def run(node_class: type[Node], args: list[str] | None = None) -> int:
    """Console entry point: init, spin until shutdown, clean up; parameter errors exit 2."""
    rclpy.init(args=args)
    node = None
    try:
        node = node_class()
        rclpy.spin(node)
    except ValueError as err:  # invalid parameters: say which and stop
        print(f"{node_class.__name__}: {err}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
