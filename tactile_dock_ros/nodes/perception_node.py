"""perception: the terrain prior (ShapeDistribution on ``terrain_prior``, latched).

``prior_source: problem`` publishes the prior of a benchmark problem at start (the mock profile:
the mock terrain is drawn from that same prior). ``prior_source: depth`` builds the prior from a
depth Image + CameraInfo (``depth/image``, ``depth/camera_info``, sensor-data QoS) with the
ROS-free ``perception`` package, on the first valid frame (``capture: first_frame``) or on each
``~/capture`` request (std_srvs/Trigger; ``capture: on_request``). RViz markers on ``~/markers``.
"""

from __future__ import annotations

from rclpy.node import Node
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.msg import ShapeDistribution
from tactile_dock_ros.nodes import convert, markers, qos
from tactile_dock_ros.nodes.common import PLANE_TABLE, Stopwatch, header, run
from tactile_dock_ros.nodes.params import Param, declare

PARAMS = [
    *PLANE_TABLE,
    Param("prior_source", "depth", "where the prior comes from", choices=("depth", "problem")),
    Param(
        "problem",
        "sloper",
        "benchmark problem (prior_source: problem)",
        choices=tuple(problems.names()),
    ),
    Param(
        "capture",
        "first_frame",
        "when to build the prior from depth",
        choices=("first_frame", "on_request"),
    ),
]


class PerceptionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("perception", **kwargs)
        self.p = declare(self, PARAMS)
        self.prior_pub = self.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        self.marker_pub = self.create_publisher(MarkerArray, "~/markers", qos.LATCHED)
        self.create_service(Trigger, "~/capture", self.on_capture)
        if self.p.prior_source == "problem":
            self.publish_prior(problems.get(self.p.problem).prior, "problem " + self.p.problem)
        else:
            raise ValueError("prior_source: depth needs the perception package (not merged yet)")

    def publish_prior(self, prior: GaussianShape, source: str, seconds: float = 0.0) -> None:
        stamp = header(self, self.p.plane_frame_id)
        self.prior_pub.publish(convert.shape_to_msg(prior, stamp))
        mean = prior.mean_vertices[None]
        self.marker_pub.publish(markers.samples_and_history(mean, History(), stamp))
        self.get_logger().info(
            f"prior from {source}: {prior.n_vertices} vertices, {prior.n_basis} basis columns, "
            f"{seconds:.3f} s"
        )

    def on_capture(self, request, response):
        if self.p.prior_source == "problem":
            with Stopwatch() as watch:
                prior = problems.get(self.p.problem).prior
            self.publish_prior(prior, "problem " + self.p.problem, watch.seconds)
            response.success, response.message = True, "prior republished"
        return response


def main(args: list[str] | None = None) -> int:
    return run(PerceptionNode, args)
