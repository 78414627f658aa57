"""Build a node of the suite in-process, in its own rclpy context, from launch-file settings."""

import contextlib
import dataclasses
from collections.abc import Iterator

import rclpy
from conftest import REPO_ROOT
from geometry_msgs.msg import PoseStamped
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


@dataclasses.dataclass
class PlannerDriver:
    """A driver node's ends of the planner's topics (``planner_driver``)."""

    statuses: list  # episode_status received
    plans: list  # plans received
    prior: object  # terrain_prior publisher
    history: object  # contact_history publisher
    samples: object  # shape_samples publisher
    pose: object  # tool_pose publisher

    def matched(self) -> bool:
        """Whether the planner subscribed every publisher."""
        publishers = (self.prior, self.history, self.samples, self.pose)
        return all(p.get_subscription_count() for p in publishers)


def planner_driver(driver: Node, prior=None) -> PlannerDriver:
    """Record episode_status and plan on ``driver`` and publish what the planner subscribes
    (``prior``: a terrain_prior publisher made elsewhere, else one made here, latched)."""
    from tactile_dock_ros.msg import (
        ContactHistory,
        DockingPlan,
        EpisodeStatus,
        ShapeDistribution,
        ShapeSamples,
    )

    from tactile_dock_ros.nodes import qos

    statuses, plans = [], []
    driver.create_subscription(EpisodeStatus, "episode_status", statuses.append, qos.LATCHED)
    driver.create_subscription(DockingPlan, "plan", plans.append, qos.EVENTS)
    return PlannerDriver(
        statuses,
        plans,
        prior or driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED),
        driver.create_publisher(ContactHistory, "contact_history", qos.LATCHED),
        driver.create_publisher(ShapeSamples, "shape_samples", qos.LATCHED),
        driver.create_publisher(PoseStamped, "/arm/tool_pose", qos.SENSOR),
    )


@dataclasses.dataclass
class PlannerEpisode:
    """A running episode of the in-process planner (``planner_episode``): its node, the
    executor spinning it and the driver's publishers and records."""

    node: Node
    executor: object
    shape: object  # the sloper problem's prior, published as terrain_prior
    stamp: object  # a Header stamped after the episode started
    samples: object  # shape_samples publisher
    pose: object  # tool_pose publisher
    statuses: list
    plans: list
    driver: Node  # the node playing the others
    history: object  # contact_history publisher


@contextlib.contextmanager
def planner_episode(params_dir, extra_args: list[str] = ()) -> Iterator[PlannerEpisode]:
    """The mock profile's planner in-process (``extra_args``: more ROS arguments), a driver
    playing the other nodes: the sloper prior published, an episode started, an empty contact
    history published."""
    from ros_helpers import spin_until
    from std_srvs.srv import Trigger

    from tactile_dock_ros.core import problems
    from tactile_dock_ros.core.episode import EpisodeState
    from tactile_dock_ros.nodes import convert

    spec = launch_nodes("mock")["planner"]
    with node_with_driver(spec, params_dir, extra_args) as (node, driver, executor):
        ends = planner_driver(driver)
        start = driver.create_client(Trigger, "start_episode")
        assert spin_until(executor, lambda: start.service_is_ready() and ends.matched(), 10.0)
        shape = problems.get("sloper").prior
        ends.prior.publish(convert.shape_to_msg(shape, convert.Header()))
        assert spin_until(executor, lambda: node.prior is not None, 10.0)
        future = start.call_async(Trigger.Request())
        assert spin_until(executor, future.done, 10.0) and future.result().success
        stamp = convert.Header(stamp=driver.get_clock().now().to_msg())
        ends.history.publish(convert.history_to_msg(EpisodeState(), stamp))
        yield PlannerEpisode(
            node, executor, shape, stamp, ends.samples, ends.pose, ends.statuses, ends.plans,
            driver, ends.history,
        )  # fmt: skip


def pose_msg(x: float, y: float, z: float) -> PoseStamped:
    """A tool pose at (x, y, z) metres in the base frame, identity orientation."""
    msg = PoseStamped()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
    msg.pose.orientation.w = 1.0
    return msg
