"""mock_hardware: simulated arm + F/T sensor on a ground-truth terrain (docs/nodes.md).

Integrates ``cmd_twist`` (TwistStamped, base frame; a command older than ``command_timeout``
counts as zero) within the arm's own limits, as a real driver enforces them whatever its
commander sends (``execution.mock_physics.limit_command``: ``max_speed``, the box
``workspace_min``/``workspace_max`` in the plane frame like the executor's, a throttled warning
when a command is clamped), for a point tool against the terrain with
``execution.mock_physics`` at ``rate_hz`` and publishes ``tool_pose`` (PoseStamped) and
``wrench`` (WrenchStamped, environment force on the tool plus a constant bias and Gaussian
noise). The terrain is drawn from a benchmark problem
with a seed, or read from a YAML file (``vertices: [[x, y], ...]``, ``start: [x, y]``, optional
``closed``, ``friction``). ``~/ground_truth`` (ShapeDistribution with no basis, latched) shows
the truth for RViz, plots and tests; the planner never subscribes to it. With
``perception_config`` set, a depth camera at that file's extrinsic, displaced by
``calibration_error`` (the deliberate miscalibration), renders the terrain with the file's depth
noise and real occlusion (``perception.render``), published on ``depth/image`` and
``depth/camera_info``. Fault injection: ``~/drop_wrench`` and ``~/drop_pose`` (std_srvs/SetBool)
stop (true) or resume (false) that sensor stream while the arm keeps moving on its last command,
as a crashed F/T driver or a lost pose feed would.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import SetBool

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.execution.mock_physics import PointToolSim, limit_command
from tactile_dock_ros.msg import ShapeDistribution
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.nodes.common import (
    PLANE_TABLE,
    header,
    now_seconds,
    plane_frame,
    run,
    subscribe,
    workspace_box,
)
from tactile_dock_ros.nodes.params import Param, declare
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.mock_camera import MockCamera

# A command older than this counts as zero: its commander is gone (killed, hung). 2.5 periods
# of the executor's 100 Hz loop: one late tick does not stop the arm, and the last command of a
# SIGKILLed executor (0.2 m/s) moves it 5 mm (median of 5, max 6 mm; 39 mm with the former
# 0.2 s: ``bench safety --parts exit``). On a loaded machine (load average 3 on 2 cores) the
# executor itself sent nothing for 25-260 ms about once a second (command stamp intervals p99
# 35-55 ms): the arm pauses then, as a real driver must when its commander is late.
COMMAND_TIMEOUT_S = 0.025
LIMIT_LOG_PERIOD_S = 1.0  # seconds between two warnings that the arm clamped a command

PARAMS = [
    *PLANE_TABLE,
    Param(
        "problem",
        "sloper",
        "benchmark problem the terrain is drawn from",
        choices=tuple(problems.names()),
    ),
    Param("seed", 0, "seed of the ground-truth draw", "", 0, 2**31 - 1),
    Param("terrain_file", "", "YAML terrain file; overrides problem and seed when set"),
    Param("rate_hz", 200.0, "simulation and sensor publication rate", "Hz", 1.0, 2000.0),
    Param("stiffness", 500.0, "arm stiffness along the motion", "N/m", 1.0, 1e6),
    Param("lateral_stiffness", 25.0, "arm stiffness across the motion", "N/m", 0.01, 1e6),
    Param("max_slide_speed", 0.3, "fastest slide along the surface", "m/s", 1e-3, 10.0),
    Param(
        "command_timeout",
        COMMAND_TIMEOUT_S,
        "a command older than this counts as zero (the commander is gone)",
        "s",
        0.001,
        5.0,
    ),
    Param(
        "max_speed",
        0.3,
        "the arm's own speed limit: faster commands are scaled down",
        "m/s",
        1e-3,
        10.0,
    ),
    *workspace_box([-1.1, -1.1], [1.1, 1.1], "the arm's own box"),
    Param("pose_noise", 0.0001, "tool position noise (std per axis)", "m", 0.0, 0.01),
    Param("force_noise", 0.05, "force noise (std per axis)", "N", 0.0, 10.0),
    Param(
        "force_bias",
        [0.3, -0.2, 0.5],
        "constant F/T bias in the base frame",
        "N",
        -100,
        100,
        length=3,
    ),
    Param("noise_seed", 1, "seed of the sensor noise", "", 0, 2**31 - 1),
    Param("perception_config", "", "camera pose and depth noise (YAML); '' = no camera"),
    Param(
        "calibration_error",
        [0.01, -0.01, 0.0, 0.0, 0.0, 0.017],
        "true camera pose minus the configured one (tx ty tz, rx ry rz)",
        "m, rad",
        -0.5,
        0.5,
        length=6,
    ),
    Param("camera_rate_hz", 2.0, "depth image publication rate", "Hz", 0.1, 60.0),
    Param(
        "image_size",
        [MockCamera.width, MockCamera.height],
        "depth image width, height",
        "px",
        8,
        4096,
        length=2,
    ),
    Param("focal_px", MockCamera.focal_px, "focal length of the mock depth camera", "px", 1.0, 1e5),
]


def load_terrain(problem: str, seed: int, terrain_file: str):
    """(vertices (n, 2), closed, friction, start (2,)) from a file or a problem + seed."""
    if terrain_file:
        data = yaml.safe_load(Path(terrain_file).read_text())
        vertices = np.asarray(data["vertices"], float)
        start = np.asarray(data["start"], float)
        return vertices, bool(data.get("closed", False)), float(data.get("friction", 0.5)), start
    spec = problems.get(problem)
    truth = spec.sample_ground_truth(np.random.default_rng(seed))
    return truth, spec.prior.closed, spec.friction, spec.start


class MockHardwareNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("mock_hardware", **kwargs)
        self.p = declare(self, PARAMS)
        if np.any(np.asarray(self.p.workspace_min) >= np.asarray(self.p.workspace_max)):
            raise ValueError("parameter workspace_min must be below workspace_max")
        self.plane = plane_frame(self.p)
        vertices, closed, friction, start = load_terrain(
            self.p.problem, self.p.seed, self.p.terrain_file
        )
        self.sim = PointToolSim(
            vertices,
            closed,
            friction,
            self.p.stiffness,
            start,
            self.p.lateral_stiffness,
            self.p.max_slide_speed,
        )
        self.rng = np.random.default_rng(self.p.noise_seed)
        self.dt = 1.0 / self.p.rate_hz
        self.velocity = np.zeros(2)
        self.command_time = None
        self.timeouts = 0  # moving commands stopped for their age
        self.pose_pub = self.create_publisher(PoseStamped, "tool_pose", qos.SENSOR)
        self.wrench_pub = self.create_publisher(WrenchStamped, "wrench", qos.SENSOR)
        truth_pub = self.create_publisher(ShapeDistribution, "~/ground_truth", qos.LATCHED)
        truth = GaussianShape(vertices.ravel(), np.zeros((vertices.size, 0)), closed, friction)
        truth_pub.publish(convert.shape_to_msg(truth, header(self, self.p.plane_frame_id)))
        base_id = self.p.base_frame_id
        subscribe(self, TwistStamped, "cmd_twist", self.on_command, qos.COMMAND, base_id)
        self.dropped = {"wrench": False, "pose": False}
        for stream in self.dropped:
            self.create_service(SetBool, f"~/drop_{stream}", self.drop_service(stream))
        self.create_timer(self.dt, self.on_tick)
        if self.p.perception_config:
            self.start_camera(vertices)
        self.get_logger().info(
            f"terrain: {len(vertices)} vertices, friction {friction}, tool starts at {start}"
        )

    def start_camera(self, vertices: np.ndarray) -> None:
        """Render the depth image once (static terrain) and publish it at the camera rate."""
        try:
            config = PerceptionConfig.load(self.p.perception_config)
        except (OSError, PerceptionError) as err:
            raise ValueError(f"parameter perception_config: {err}") from err
        camera = MockCamera(*self.p.image_size, self.p.focal_px)
        depth = camera.render(vertices, config, np.asarray(self.p.calibration_error), self.rng)
        image_pub = self.create_publisher(Image, "depth/image", qos.SENSOR)
        info_pub = self.create_publisher(CameraInfo, "depth/camera_info", qos.SENSOR)

        def publish() -> None:
            stamp = header(self, "depth_camera")
            info_pub.publish(convert.camera_info(camera.K, camera.width, camera.height, stamp))
            image_pub.publish(convert.depth_to_image(depth, stamp))

        self.create_timer(1.0 / self.p.camera_rate_hz, publish)

    def drop_service(self, stream: str):
        def drop(request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
            self.dropped[stream] = request.data
            response.success = True
            response.message = f"{stream} {'stopped' if request.data else 'publishing'}"
            self.get_logger().warning(f"fault injection: {response.message}")
            return response

        return drop

    def on_command(self, msg: TwistStamped) -> None:
        self.velocity = convert.twist_velocity(msg, self.plane)
        self.command_time = now_seconds(self)

    def on_tick(self) -> None:
        age = None if self.command_time is None else now_seconds(self) - self.command_time
        fresh = age is not None and age <= self.p.command_timeout
        if not fresh and np.any(self.velocity != 0.0):  # the commander fell silent mid-move
            self.timeouts += 1
            self.velocity = np.zeros(2)
            self.get_logger().warning(
                f"no command for {age * 1e3:.0f} ms: stopped ({self.timeouts} times so far)",
                throttle_duration_sec=LIMIT_LOG_PERIOD_S,
            )
        velocity, reasons = limit_command(
            self.velocity if fresh else np.zeros(2),
            self.sim.tool,
            self.dt,
            self.p.max_speed,
            self.p.workspace_min,
            self.p.workspace_max,
        )
        if reasons:
            self.get_logger().warning(
                f"command clamped: {'; '.join(reasons)}", throttle_duration_sec=LIMIT_LOG_PERIOD_S
            )
        self.sim.step(velocity, self.dt)
        stamp = header(self, self.p.base_frame_id)
        position = self.plane.point_from_plane(self.sim.tool) + self.rng.normal(
            0.0, self.p.pose_noise, 3
        )
        force = (
            self.plane.vector_from_plane(self.sim.force)
            + np.asarray(self.p.force_bias)
            + self.rng.normal(0.0, self.p.force_noise, 3)
        )
        if not self.dropped["pose"]:
            self.pose_pub.publish(convert.pose_to_msg(position, stamp))
        if not self.dropped["wrench"]:
            self.wrench_pub.publish(convert.wrench_to_msg(force, stamp))


def main(args: list[str] | None = None) -> int:
    return run(MockHardwareNode, args)
