"""perception: the terrain prior (ShapeDistribution on ``terrain_prior``, latched), the captured
holds and their first-look evaluation (``/evaluate_hold``).

``prior_source: depth`` (the default, the robot's prior) builds the prior from a depth Image +
CameraInfo (``depth/image``, ``depth/camera_info``, sensor-data QoS) with the ROS-free
``perception`` package and the settings file ``perception_config`` (camera extrinsic and its
covariance, depth noise, slicing, occlusion), on the first valid frame (``capture:
first_frame``) or on the next frame after each ``~/capture`` request (std_srvs/Trigger;
``capture: on_request``). A frame the perception cannot use is logged and skipped. The image
conditions the terrain classes of ``terrain_classes`` (``tools.fit_terrain_classes``,
``perception.prior_select``): the best class's posterior when it explains at least
``min_inlier_fraction`` of the slice (-1: the class's own gate, fitted on training scans),
else, out of library, the generic depth prior of that image with a warning. Without
``terrain_classes`` (or with ``prior_source: generic``) every image gets the generic depth prior
(paper Sec. III-A1), whose P_dock are overconfident (docs/benchmarks.md); ``learned`` is the
earlier name of ``depth``. ``prior_source: problem`` publishes the prior of a benchmark problem
instead (fast and exact; the mock terrain is drawn from that same prior). RViz markers on
``~/markers``; ``~/status`` (DiagnosticStatus, latched) carries the compute time and, with a
class library, the model used (``learned`` / ``generic``), the class, its inlier fraction, the
gate and each class's log evidence.

Decision: ``ShapeDistribution`` is unchanged for the learned prior (its posterior is the same
Gaussian over vertices, which the message carries exactly); the class and the gate's decision
go to ``~/status`` and the log, so bags recorded before still replay.

Holds: every prior built (the first frame, each ``~/capture``, the problem's prior) is also kept
as a hold (id from 1, capture stamp, prior) in a ``core.holds.HoldStore`` of ``max_holds``
entries, the oldest dropped with a log; ``~/capture`` answers the id the capture gets ("hold N:
..."). ``terrain_prior`` carries each new prior with its ``hold_id``, latched with the last
``max_holds`` (``qos.priors``: a node started later receives every kept hold, oldest first): the
planner and inference keep them by id too, so a ``/dock`` goal docks on the hold it names.
``/evaluate_hold`` (``EvaluateHold``) returns per requested hold what the planner's first cycle
would plan on it (``core.holds.evaluate_hold``: ``evaluate_samples`` prior draws seeded with
``evaluate_seed``, ``core.planner.plan`` with the planner's settings) from the latest
``tool_pose`` or a given position, without moving the arm; an unknown id is answered
``found: false`` with a reason.

Decision: this node serves ``/evaluate_hold`` because it owns the holds; the planner's settings
it needs are read-only parameters declared here from the planner's own table
(``planner_node.CONFIG_SETTINGS`` of ``planner_node.PARAMS``, same defaults; the profiles give
both nodes the same workspace box, test_holds checks the two configs agree). The planner would need
every prior sent to it (a new topic or a service call per request) and would block its episode
loop, whose plan resends are the executor's heartbeat, for ~10-100 ms per hold; this node is idle
between captures.
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.holds import HoldStore, evaluate_hold
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.msg import HoldEvaluation, ShapeDistribution
from tactile_dock_ros.nodes import convert, markers, planner_node, qos
from tactile_dock_ros.nodes.common import (
    MAX_HOLDS,
    PLANE_TABLE,
    Stopwatch,
    header,
    plane_frame,
    run,
    subscribe,
)
from tactile_dock_ros.nodes.params import Param, declare
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.learned_prior import TerrainLibrary
from tactile_dock_ros.perception.prior_select import (
    PRIOR_SOURCES,
    SOURCE_ALIASES,
    SelectedPrior,
    gate_thresholds,
    prior_source,
    select_prior,
)
from tactile_dock_ros.perception.terrain_prior import perceive
from tactile_dock_ros.srv import EvaluateHold

# the planner's settings of core.planner.plan, for /evaluate_hold (the module docstring)
PARAMS = [
    *PLANE_TABLE,  # the prior's plane comes from perception_config; the tool pose's from these
    Param(
        "prior_source",
        "depth",
        "where the prior comes from: depth (terrain_classes on the depth image), generic (the "
        "generic depth prior), problem (a benchmark problem's); learned: the earlier name of depth",
        choices=(*PRIOR_SOURCES, *SOURCE_ALIASES),
    ),
    Param(
        "problem",
        "sloper",
        "benchmark problem (prior_source: problem)",
        choices=tuple(problems.names()),
    ),
    Param("perception_config", "", "perception settings YAML (prior_source: depth, generic)"),
    Param(
        "terrain_classes",
        "",
        "terrain class library .npz of tools.fit_terrain_classes (prior_source: depth; empty: "
        "the generic depth prior)",
    ),
    Param(
        "min_inlier_fraction",
        -1.0,
        "out-of-library gate: least fraction of slice bins the best class must explain, "
        "else the generic depth prior is used (-1: each class's fitted gate)",
        "",
        -1.0,
        1.0,
    ),
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
    MAX_HOLDS,
    Param("evaluate_samples", 100, "prior draws per /evaluate_hold evaluation", "", 2, 100000),
    Param("evaluate_seed", 0, "seed of each /evaluate_hold evaluation's draws", "", 0, 2**31 - 1),
    *(p for p in planner_node.PARAMS if p.name in planner_node.CONFIG_SETTINGS),
]


class PerceptionNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("perception", **kwargs)
        self.p = declare(self, PARAMS)
        self.planner_config = planner_node.planner_config(self.p)
        self.plane = plane_frame(self.p)
        self.rng = np.random.default_rng(self.p.seed)
        self.holds = HoldStore(self.p.max_holds)
        self.tool = None  # (2,) the latest tool position in the plane
        self.prior_pub = self.create_publisher(
            ShapeDistribution, "terrain_prior", qos.priors(self.p.max_holds)
        )
        self.marker_pub = self.create_publisher(MarkerArray, "~/markers", qos.LATCHED)
        self.status_pub = self.create_publisher(DiagnosticStatus, "~/status", qos.LATCHED)
        self.create_service(Trigger, "~/capture", self.on_capture)
        self.create_service(EvaluateHold, "evaluate_hold", self.on_evaluate)
        base = self.p.base_frame_id
        subscribe(self, PoseStamped, "tool_pose", self.on_pose, qos.SENSOR, base)
        self.info = None
        self.pending = self.p.capture == "first_frame"
        self.source = prior_source(self.p.prior_source)
        if self.source == "problem":
            with Stopwatch() as watch:
                prior = problems.get(self.p.problem).prior
            self.publish_prior(prior, "problem " + self.p.problem, watch.seconds)
            return
        source = self.source
        if not self.p.perception_config:
            raise ValueError(f"parameter perception_config is required for prior_source: {source}")
        try:
            self.config = PerceptionConfig.load(self.p.perception_config)
        except (OSError, PerceptionError) as err:
            raise ValueError(f"parameter perception_config: {err}") from err
        self.library = None
        fraction = self.p.min_inlier_fraction
        self.gate_override = None if fraction < 0 else fraction  # None: each class's own gate
        if source == "depth" and self.p.terrain_classes:
            self.library, gates = load_library(self.p.terrain_classes, self.gate_override)
            listed = ", ".join(f"{name} {gate:.3f}" for name, gate in gates.items())
            self.get_logger().info(
                f"depth prior: terrain classes of {self.p.terrain_classes}, out-of-library gates "
                f"(fraction of slice bins) {listed}"
            )
        elif source == "depth":
            self.get_logger().warning(
                "depth prior without terrain_classes: every image gets the generic depth prior, "
                "whose P_dock are overconfident; fit a class library of your wall "
                "(tools.fit_terrain_classes, tools.refit_terrain_classes)"
            )
        camera = self.p.camera_frame_id or None
        subscribe(self, CameraInfo, "depth/camera_info", self.on_info, qos.SENSOR, camera)
        subscribe(self, Image, "depth/image", self.on_image, qos.SENSOR, camera)

    def on_capture(self, request, response):
        hold = f"hold {self.holds.next_id}"  # the id the capture gets (captures go in turn)
        if self.source == "problem":
            self.publish_prior(problems.get(self.p.problem).prior, "problem " + self.p.problem)
            response.success, response.message = True, f"{hold}: prior republished"
        else:
            self.pending = True
            response.success = True
            response.message = f"{hold}: the next valid depth frame is used"
        return response

    def on_pose(self, msg: PoseStamped) -> None:
        self.tool = convert.pose_position(msg, self.plane)

    def on_evaluate(self, request, response):
        """``EvaluateHold``: the first cycle's plan per requested hold; changes no state."""
        ids = [int(i) for i in request.hold_ids] or self.holds.ids()
        tool = self.tool
        if request.use_tool_position:
            try:
                tool = convert.point_xy("tool_position", request.tool_position)
            except convert.MessageError as err:
                response.success, response.message = False, str(err)
                return response
        elif tool is None:
            response.success = False
            response.message = "no tool position yet (tool_pose); set use_tool_position"
            return response
        response.holds = [self.evaluate(hold_id, tool) for hold_id in ids]
        found = [h for h in response.holds if h.found]
        response.success = True
        response.message = f"{len(found)} of {len(ids)} holds evaluated from tool {tool.round(4)}"
        self.get_logger().info(
            response.message
            + "".join(f"; hold {h.hold_id}: P_dock {h.path_docking_probability:.3f}" for h in found)
        )
        return response

    def evaluate(self, hold_id: int, tool: np.ndarray) -> HoldEvaluation:
        hold = self.holds.get(hold_id)
        if hold is None:
            return convert.hold_not_evaluated_msg(
                hold_id, f"no hold {hold_id} (kept: {self.holds.ids()})"
            )
        p = self.p
        captured = Header(stamp=Time(nanoseconds=hold.stamp).to_msg(), frame_id=p.plane_frame_id)
        try:
            result = evaluate_hold(
                hold.prior, tool, self.planner_config, p.evaluate_samples, p.evaluate_seed
            )
        except ValueError as err:  # a prior the planner cannot take: said, never raised
            self.get_logger().error(f"hold {hold_id} not evaluated: {err}")
            return convert.hold_not_evaluated_msg(hold_id, f"not evaluated: {err}", captured)
        return convert.hold_evaluation_to_msg(hold_id, result, captured)

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
        source = f"depth {msg.width}x{msg.height}"
        values: list[KeyValue] = []
        fell_back = False
        with Stopwatch() as watch:
            try:
                if self.library is None:
                    prior = perceive(depth, K, self.config, self.rng).prior
                else:
                    chosen = select_prior(
                        depth, K, self.config, self.library, self.rng, self.gate_override
                    )
                    prior, values = chosen.prior, learned_status(chosen)
                    source += f", {chosen.model} prior: {chosen.reason}"
                    fell_back = chosen.model == "generic"
            except PerceptionError as err:
                self.get_logger().warning(f"no prior from this frame: {err}")
                return
        self.pending = False
        if fell_back:
            self.get_logger().warning(f"prior from {source}")
        self.publish_prior(prior, source, watch.seconds, values)

    def publish_prior(
        self,
        prior: GaussianShape,
        source: str,
        seconds: float = 0.0,
        values: list[KeyValue] | None = None,
    ) -> None:
        """Keep ``prior`` as a new hold and publish it (``terrain_prior``, markers, status with
        ``values`` appended)."""
        stamp = header(self, self.p.plane_frame_id)
        hold, dropped = self.holds.add(Time.from_msg(stamp.stamp).nanoseconds, prior)
        if dropped is not None:
            self.get_logger().info(
                f"hold {dropped.hold_id} dropped: {self.p.max_holds} holds are kept (max_holds)"
            )
        self.prior_pub.publish(convert.shape_to_msg(prior, stamp, hold.hold_id))
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
                    KeyValue(key="hold_id", value=str(hold.hold_id)),
                    *(values or []),
                ],
            )
        )
        self.get_logger().info(
            f"hold {hold.hold_id}, prior from {source}: {prior.n_vertices} vertices, "
            f"{prior.n_basis} basis columns, {seconds:.3f} s"
        )


def load_library(
    path: str, min_inlier_fraction: float | None
) -> tuple[TerrainLibrary, dict[str, float]]:
    """The class library at ``path`` and the gate to apply per class (``min_inlier_fraction``
    None: each class's own); ValueError naming the parameter when either is unusable."""
    try:
        library = TerrainLibrary.load(path)
    except (OSError, ValueError) as err:
        raise ValueError(f"parameter terrain_classes: {err}") from err
    try:
        gates = gate_thresholds(library, min_inlier_fraction)
    except ValueError as err:
        raise ValueError(f"parameter min_inlier_fraction: {err}") from err
    return library, gates


def learned_status(chosen: SelectedPrior) -> list[KeyValue]:
    """``~/status`` values of a learned-prior capture: model, class, inlier fraction, gate and
    each class's log evidence (``log_evidence/<class>``)."""
    return [
        KeyValue(key="model", value=chosen.model),
        KeyValue(key="class", value=chosen.class_name),
        KeyValue(key="best_class", value=chosen.learned.name),
        KeyValue(key="inlier_fraction", value=f"{chosen.learned.inlier_fraction:.4f}"),
        KeyValue(key="min_inlier_fraction", value=f"{chosen.min_inlier_fraction:.4f}"),
        *(
            KeyValue(key=f"log_evidence/{name}", value=f"{value:.3f}")
            for name, value in chosen.learned.log_evidence.items()
        ),
    ]


def main(args: list[str] | None = None) -> int:
    return run(PerceptionNode, args)
