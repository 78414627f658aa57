"""Build a node of the suite in-process, in its own rclpy context, from launch-file settings."""

import contextlib
from collections.abc import Iterator

import rclpy
from conftest import REPO_ROOT
from rclpy.context import Context
from rclpy.node import Node

from tactile_dock_ros.nodes.common import node_class
from tactile_dock_ros.tools import launch_xml

LAUNCH_FILE = REPO_ROOT / "launch" / "tactile_dock.launch.xml"
SHARE = {"tactile_dock_ros": REPO_ROOT}


def launch_nodes(profile: str, **arguments: str) -> dict:
    """Node name -> NodeLaunch declared by the launch file for ``profile`` (no state journals
    unless ``state_directory`` is given: tests never resume each other's episodes)."""
    arguments = {"profile": profile, "state_directory": "", **arguments}
    nodes = launch_xml.parse(LAUNCH_FILE, SHARE, arguments)
    return {n.name: n for n in nodes}


@contextlib.contextmanager
def node_from_launch(
    spec, params_dir, extra_args: list[str] = ()
) -> Iterator[tuple[Node, Context]]:
    """Instantiate the node ``spec`` with its launch parameters and remappings (argv form)."""
    argv = spec.command(REPO_ROOT / "scripts", params_dir)
    cli_args = argv[argv.index("--ros-args") :] + list(extra_args)
    context = Context()
    rclpy.init(context=context)
    node = None
    try:
        node = node_class(spec.executable)(context=context, cli_args=cli_args)
        yield node, context
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.shutdown(context=context)


@contextlib.contextmanager
def node_with_driver(spec, params_dir, extra_args: list[str] = (), executor_class=None):
    """The node ``spec`` plus a 'driver' node in the same context, and an executor of both
    (``executor_class(context=...)``, single-threaded by default)."""
    from rclpy.executors import SingleThreadedExecutor

    with node_from_launch(spec, params_dir, extra_args) as (node, context):
        driver = Node("test_driver", context=context)
        executor = (executor_class or SingleThreadedExecutor)(context=context)
        executor.add_node(node)
        executor.add_node(driver)
        try:
            yield node, driver, executor
        finally:
            executor.shutdown()
            driver.destroy_node()
