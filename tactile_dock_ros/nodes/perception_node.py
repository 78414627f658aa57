"""perception: the terrain prior (ShapeDistribution on ``terrain_prior``, latched).

``prior_source: depth`` builds the prior from a depth Image + CameraInfo (``depth/image``,
``depth/camera_info``, sensor-data QoS) with the ROS-free ``perception`` package and the
settings file ``perception_config`` (camera extrinsic and its covariance, depth noise, slicing,
occlusion), on the first valid frame (``capture: first_frame``) or on the next frame after each
``~/capture`` request (std_srvs/Trigger; ``capture: on_request``). A frame the perception
cannot use is logged and skipped. ``prior_source: problem`` publishes the prior of a benchmark
problem instead (fast and exact; the mock terrain is drawn from that same prior). RViz markers
on ``~/markers``; ``~/status`` (DiagnosticStatus, latched) carries the compute time.
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.msg import ShapeDistribution
from tactile_dock_ros.nodes import convert, markers, qos
from tactile_dock_ros.nodes.common import PLANE_FRAME_ID, Stopwatch, header, run, subscribe
from tactile_dock_ros.nodes.params import Param, declare
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.terrain_prior import perceive

PARAMS = [
    PLANE_FRAME_ID,  # the plane itself comes from perception_config (T_plane_camera)
    Param("prior_source", "depth", "where the prior comes from", choices=("depth", "problem")),
    Param(
        "problem",
        "sloper",
        "benchmark problem (prior_source: problem)",
        choices=tuple(problems.names()),
    ),
    Param("perception_config", "", "perception settings YAML (prior_source: depth)"),
    Param(
        "capture",
        "first_frame",
        "when to build the prior from depth",
        choices=("first_frame", "on_request"),
    ),
    Param("seed", 0, "seed of the occlusion sampler", "", 0, 2**31 - 1),
    Param(
        "camera_frame_id",
        "",
        "frame of the depth image and camera info ('': any, the two must agree)",
    ),
]


class PerceptionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("perception", **kwargs)
        self.p = declare(self, PARAMS)
        self.rng = np.random.default_rng(self.p.seed)
        self.prior_pub = self.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        self.marker_pub = self.create_publisher(MarkerArray, "~/markers", qos.LATCHED)
        self.status_pub = self.create_publisher(DiagnosticStatus, "~/status", qos.LATCHED)
        self.create_service(Trigger, "~/capture", self.on_capture)
        self.info = None
        self.pending = self.p.capture == "first_frame"
        if self.p.prior_source == "problem":
            with Stopwatch() as watch:
                prior = problems.get(self.p.problem).prior
            self.publish_prior(prior, "problem " + self.p.problem, watch.seconds)
            return
        if not self.p.perception_config:
            raise ValueError("parameter perception_config is required for prior_source: depth")
        try:
            self.config = PerceptionConfig.load(self.p.perception_config)
        except (OSError, PerceptionError) as err:
            raise ValueError(f"parameter perception_config: {err}") from err
        camera = self.p.camera_frame_id or None
        subscribe(self, CameraInfo, "depth/camera_info", self.on_info, qos.SENSOR, camera)
        subscribe(self, Image, "depth/image", self.on_image, qos.SENSOR, camera)

    def on_capture(self, request, response):
        if self.p.prior_source == "problem":
            self.publish_prior(problems.get(self.p.problem).prior, "problem " + self.p.problem)
            response.success, response.message = True, "prior republished"
        else:
            self.pending = True
            response.success, response.message = True, "the next valid depth frame is used"
        return response

    def on_info(self, msg: CameraInfo) -> None:
        convert.intrinsics_from_camera_info(msg)  # K alone; the image size is checked with it
        self.info = msg

    def on_image(self, msg: Image) -> None:
        """Every frame is checked (a bad camera is reported while idle too); used when pending."""
        depth = convert.depth_from_image(msg)
        if self.info is None:
            return
        K = convert.intrinsics_from_camera_info(self.info, msg)
        if not self.pending:
            return
        with Stopwatch() as watch:
            try:
                result = perceive(depth, K, self.config, self.rng)
            except PerceptionError as err:
                self.get_logger().warning(f"no prior from this frame: {err}")
                return
        self.pending = False
        self.publish_prior(result.prior, f"depth {msg.width}x{msg.height}", watch.seconds)

    def publish_prior(self, prior: GaussianShape, source: str, seconds: float = 0.0) -> None:
        stamp = header(self, self.p.plane_frame_id)
        self.prior_pub.publish(convert.shape_to_msg(prior, stamp))
        self.marker_pub.publish(
            markers.samples_and_history(prior.mean_vertices[None], History(), stamp)
        )
        self.status_pub.publish(
            DiagnosticStatus(
                name=f"{self.get_name()}: prior",
                message=f"prior from {source}",
                values=[
                    KeyValue(key="seconds", value=f"{seconds:.6f}"),
                    KeyValue(key="vertices", value=str(prior.n_vertices)),
                ],
            )
        )
        self.get_logger().info(
            f"prior from {source}: {prior.n_vertices} vertices, {prior.n_basis} basis columns, "
            f"{seconds:.3f} s"
        )


def main(args: list[str] | None = None) -> int:
    return run(PerceptionNode, args)
