"""Helpers for tests that talk over DDS: an isolated rclpy context and bounded waiting."""

import contextlib
import time
from collections.abc import Callable, Iterator

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node


@contextlib.contextmanager
def ros_node(name: str) -> Iterator[tuple[Node, SingleThreadedExecutor]]:
    """A node in a fresh rclpy context, with its executor; everything is shut down on exit."""
    context = Context()
    rclpy.init(context=context)
    node = Node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def spin_until(
    executor: SingleThreadedExecutor, done: Callable[[], bool], timeout_s: float
) -> bool:
    """Spin until ``done()`` holds or ``timeout_s`` passes; returns ``done()``."""
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return done()


def send_goal(executor: SingleThreadedExecutor, client, goal):
    """Send ``goal`` with the action ``client`` and return its goal handle (accepted or not)."""
    future = client.send_goal_async(goal)
    assert spin_until(executor, future.done, 10.0)
    return future.result()
