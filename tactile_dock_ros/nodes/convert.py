"""The one place where ROS messages become numpy / core types and back.

Every ``*_from_msg`` function validates what it reads (array sizes, finiteness, known status
values, unit vectors) and raises :class:`MessageError` with a message saying which field is
wrong; nodes log that message and drop the input, so a malformed message never reaches the
core or a node's state. The checks it shares with the subscription guard (``common.subscribe``:
finiteness, size limits read from the length fields, stamps, frames) are in ``nodes.validate``.
Points in the docking plane are ``geometry_msgs/Point`` with z = 0.

The message types' ROS-free counterparts (``PlaneFrame``, ``PlanCommand``, ``Report``) are in
``execution.types``; the docking plane is embedded in the robot's 3-D base frame by a
``PlaneFrame`` (tf2 is not used, so the transform is a node parameter: docs/nodes.md, "Running
it").
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import (
    Point,
    PoseStamped,
    Twist,
    TwistStamped,
    Vector3,
    Wrench,
    WrenchStamped,
)
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from tactile_dock_ros.action import Dock
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.execution.types import (
    UNIT_TOLERANCE,
    Outcome,
    PlanCommand,
    PlaneFrame,
    Report,
)
from tactile_dock_ros.msg import (
    ContactHistory,
    ContactSegment,
    DockingPlan,
    EpisodeCycle,
    EpisodeStatus,
    ExecutionReport,
    HoldEvaluation,
    SampleRequest,
    ShapeDistribution,
    ShapeSamples,
)
from tactile_dock_ros.nodes import validate
from tactile_dock_ros.nodes.validate import MessageError, finite
from tactile_dock_ros.perception import depth as depth_codec
from tactile_dock_ros.perception.config import PerceptionError

OUTCOMES = {outcome.value for outcome in Outcome}  # the ExecutionReport outcome constants


def _points(name: str, points, limit: int) -> np.ndarray:
    """(k, 2) plane coordinates of a Point list of at most ``limit``, each within
    ``validate.MAX_COORDINATE_M``; z is ignored (z = 0)."""
    validate.bounded(f"{name} count", len(points), limit)
    xy = finite(name, [(p.x, p.y) for p in points]).reshape(-1, 2)
    if np.any(np.abs(xy) > validate.MAX_COORDINATE_M):
        raise MessageError(f"{name} has a coordinate beyond {validate.MAX_COORDINATE_M:g} m")
    return xy


def plane_point(xy) -> Point:
    """A point (x, y) of the docking plane as geometry_msgs/Point (z = 0)."""
    return Point(x=float(xy[0]), y=float(xy[1]), z=0.0)


def point_xy(name: str, msg: Point) -> np.ndarray:
    """geometry_msgs/Point of the docking plane -> (2,) metres, each within
    ``validate.MAX_COORDINATE_M`` (z ignored)."""
    return validate.within(name, [msg.x, msg.y], validate.MAX_COORDINATE_M, "m")


# --------------------------------------------------------------------------- arm and sensors


def pose_position(msg, plane: PlaneFrame) -> np.ndarray:
    """geometry_msgs/PoseStamped (base frame) -> tool position in the plane (2,) metres, each
    base coordinate within ``validate.MAX_COORDINATE_M``; the orientation must be a unit
    quaternion even where it is not used."""
    pose_rotation(msg)
    p = msg.pose.position
    position = validate.within("pose.position", [p.x, p.y, p.z], validate.MAX_COORDINATE_M, "m")
    return plane.point_to_plane(position)


def pose_orientation(msg) -> np.ndarray:
    """geometry_msgs/PoseStamped -> its orientation (4,) x, y, z, w, finite (norm unchecked)."""
    q = msg.pose.orientation
    return finite("pose.orientation", [q.x, q.y, q.z, q.w])


def pose_rotation(msg) -> np.ndarray:
    """geometry_msgs/PoseStamped -> (3, 3) rotation of the tool frame into the pose's frame."""
    xyzw = pose_orientation(msg)
    if abs(np.linalg.norm(xyzw) - 1.0) > 1e-3:
        raise MessageError(f"pose.orientation must be a unit quaternion, got {xyzw.tolist()}")
    return Rotation.from_quat(xyzw).as_matrix()


def wrench_force(msg) -> np.ndarray:
    """geometry_msgs/WrenchStamped -> force (3,) newtons in the message's frame; every force
    and torque component (the torque is unused) within ``validate.MAX_FORCE_N``."""
    t = msg.wrench.torque
    validate.within("wrench.torque", [t.x, t.y, t.z], validate.MAX_FORCE_N, "N m")
    f = msg.wrench.force
    return validate.within("wrench.force", [f.x, f.y, f.z], validate.MAX_FORCE_N, "N")


def pose_to_msg(position_3: np.ndarray, header: Header) -> PoseStamped:
    """Position (3,) metres with identity orientation (the mock tool does not rotate)."""
    msg = PoseStamped(header=header)
    msg.pose.position = Point(
        x=float(position_3[0]), y=float(position_3[1]), z=float(position_3[2])
    )
    msg.pose.orientation.w = 1.0
    return msg


def wrench_to_msg(force_3: np.ndarray, header: Header) -> WrenchStamped:
    """Force (3,) newtons, zero torque."""
    return WrenchStamped(header=header, wrench=Wrench(force=vector3(force_3)))


def twist_to_msg(velocity_3: np.ndarray, header: Header) -> TwistStamped:
    """Linear velocity (3,) m/s, zero angular velocity."""
    return TwistStamped(header=header, twist=Twist(linear=vector3(velocity_3)))


def twist_velocity(msg, plane: PlaneFrame) -> np.ndarray:
    """geometry_msgs/TwistStamped -> linear velocity in the plane (2,) m/s (the angular one,
    unused, must be finite too)."""
    w = msg.twist.angular
    finite("twist.angular", [w.x, w.y, w.z])
    v = msg.twist.linear
    return plane.vector_to_plane(finite("twist.linear", [v.x, v.y, v.z]))


def vector3(v) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]) if len(v) > 2 else 0.0)


# --------------------------------------------------------------------------- shapes


def shape_to_msg(shape: GaussianShape, header: Header, hold_id: int = 0) -> ShapeDistribution:
    return ShapeDistribution(
        header=header,
        hold_id=int(hold_id),
        num_vertices=shape.n_vertices,
        mean=shape.mean.tolist(),
        num_basis=shape.n_basis,
        basis=shape.basis.ravel().tolist(),
        closed=bool(shape.closed),
        friction=float(shape.friction),
        closure_edges=list(shape.closure_edges),
    )


def shape_from_msg(msg: ShapeDistribution) -> GaussianShape:
    n = validate.bounded("num_vertices", msg.num_vertices, validate.MAX_VERTICES)
    m = validate.bounded("num_basis", msg.num_basis, validate.MAX_BASIS)
    if n < 2:
        raise MessageError(f"num_vertices must be >= 2, got {n}")
    if len(msg.mean) != 2 * n:
        raise MessageError(f"mean has {len(msg.mean)} values, expected 2*num_vertices = {2 * n}")
    if len(msg.basis) != 2 * n * m:
        raise MessageError(f"basis has {len(msg.basis)} values, expected 2n*m = {2 * n * m}")
    mean = finite("mean", msg.mean)
    basis = finite("basis", msg.basis).reshape(2 * n, m)
    try:
        return GaussianShape(
            mean,
            basis,
            closed=bool(msg.closed),
            friction=float(msg.friction),
            closure_edges=msg.closure_edges,
        )
    except ValueError as err:
        raise MessageError(str(err)) from err


# --------------------------------------------------------------------------- contact history


def segments_to_msgs(history: History, header: Header, plan_ids=0) -> list[ContactSegment]:
    """History -> ContactSegment[]; ``plan_ids`` is one id for all or one per segment."""
    ids = np.broadcast_to(np.asarray(plan_ids, dtype=int), (len(history),))
    return [
        ContactSegment(
            header=header, start=plane_point(a), end=plane_point(b), status=int(s), plan_id=int(i)
        )
        for a, b, s, i in zip(history.a, history.b, history.status, ids, strict=True)
    ]


def history_from_segments(segments) -> History:
    """ContactSegment[] -> History; unknown status, NaN or zero-length contact -> MessageError."""
    a = _points("segment start", [s.start for s in segments], validate.MAX_SEGMENTS)
    b = _points("segment end", [s.end for s in segments], validate.MAX_SEGMENTS)
    try:
        return History(a, b, np.array([s.status for s in segments], dtype=int))
    except ValueError as err:
        raise MessageError(str(err)) from err


def history_to_msg(state: EpisodeState, header: Header) -> ContactHistory:
    """The episode's history, each segment with the plan that observed it (``move_ids``)."""
    segments = segments_to_msgs(state.history, header, state.move_ids)
    return ContactHistory(header=header, segments=segments)


def history_from_msg(msg: ContactHistory, state: EpisodeState | None = None) -> EpisodeState:
    """``state`` (default: a new episode's) with the message's history and each row's plan id
    (the planner's slides, core.slides) in place of its own (``EpisodeState.with_history``)."""
    history = history_from_segments(msg.segments)
    plan_ids = np.array([s.plan_id for s in msg.segments], dtype=int)
    return (EpisodeState() if state is None else state).with_history(history, plan_ids)


# --------------------------------------------------------------------------- posterior samples


def samples_to_msg(
    vertices: np.ndarray,
    header: Header,
    method: str,
    ess: float,
    history_length: int,
    dropped=(),
    compute_time: float = 0.0,
    hold_id: int = 0,
) -> ShapeSamples:
    """``hold_id``: the hold whose prior the samples were drawn from (0: no captured hold)."""
    vertices = np.asarray(vertices, float)
    return ShapeSamples(
        hold_id=int(hold_id),
        header=header,
        num_vertices=vertices.shape[1],
        num_samples=vertices.shape[0],
        samples=vertices.ravel().tolist(),
        method=method,
        effective_sample_size=float(ess),
        history_length=int(history_length),
        dropped_segments=[int(i) for i in dropped],
        compute_time=float(compute_time),
    )


def samples_from_msg(msg: ShapeSamples) -> np.ndarray:
    """ShapeSamples -> (N, n, 2) vertices; sizes must agree, N, n must be positive and every
    coordinate within ``validate.MAX_COORDINATE_M`` (the planner also checks them against its
    prior: ``validate.samples_fit_prior``).

    An empty set (num_samples = 0, no samples) is how inference says that no shape is consistent
    with the history; callers check ``msg.num_samples == 0`` before converting.
    """
    n = validate.bounded("num_vertices", msg.num_vertices, validate.MAX_VERTICES)
    count = validate.bounded("num_samples", msg.num_samples, validate.MAX_SAMPLES)
    if n < 2 or count < 1:
        raise MessageError(f"need num_vertices >= 2 and num_samples >= 1, got {n}, {count}")
    if len(msg.samples) != count * 2 * n:
        raise MessageError(
            f"samples has {len(msg.samples)} values, expected num_samples*2n = {count * 2 * n}"
        )
    history_length = validate.bounded("history_length", msg.history_length, validate.MAX_SEGMENTS)
    validate.bounded("dropped_segments count", len(msg.dropped_segments), history_length)
    if len(msg.dropped_segments) and max(msg.dropped_segments) >= history_length:
        raise MessageError(f"dropped_segments index beyond history_length {history_length}")
    samples = validate.within("samples", msg.samples, validate.MAX_COORDINATE_M, "m")
    return samples.reshape(count, n, 2)


def sample_request_to_msg(
    header: Header, episode: int, nonce: int, hold_id: int, history_length: int, num_samples: int
) -> SampleRequest:
    """The planner's request for ``num_samples`` samples in all of ``history_length`` rows."""
    return SampleRequest(
        header=header,
        episode=int(episode),
        nonce=int(nonce),
        hold_id=int(hold_id),
        history_length=int(history_length),
        num_samples=int(num_samples),
    )


def sample_request_from_msg(msg: SampleRequest) -> dict:
    """SampleRequest -> {episode, nonce, hold_id, history_length, num_samples}; the episode id
    must not be 0, the history length and sample count within the message limits
    (``validate.MAX_SEGMENTS``, ``validate.MAX_SAMPLES``; at least 1 row and 3 samples: a
    request follows a plan on two samples at least, after a contact)."""
    if msg.episode == 0:
        raise MessageError("episode id 0 is reserved (no episode)")
    rows = validate.bounded("history_length", msg.history_length, validate.MAX_SEGMENTS)
    count = validate.bounded("num_samples", msg.num_samples, validate.MAX_SAMPLES)
    if rows < 1 or count < 3:
        raise MessageError(f"need history_length >= 1 and num_samples >= 3, got {rows}, {count}")
    return {
        "episode": int(msg.episode),
        "nonce": int(msg.nonce),
        "hold_id": int(msg.hold_id),
        "history_length": rows,
        "num_samples": count,
    }


# --------------------------------------------------------------------------- plans


def plan_to_msg(command: PlanCommand, header: Header) -> DockingPlan:
    return DockingPlan(
        header=header,
        episode=int(command.episode),
        plan_id=int(command.plan_id),
        nonce=int(command.nonce),
        history_length=int(command.history_length),
        decision=DockingPlan.DOCK if command.dock else DockingPlan.GIVE_UP,
        waypoints=[plane_point(w) for w in command.waypoints],
        load_direction=vector3(command.load),
        contact_force_threshold=float(command.force_threshold),
        max_speed=float(command.max_speed),
        compliant=bool(command.compliant),
        docking_probability=float(command.p_dock),
        objective=float(command.objective),
        target_edge=int(command.target_edge),
        target_point=plane_point(command.target_point),
        reason=command.reason,
    )


def _check_loading_move(waypoints: np.ndarray, load: np.ndarray, scalars: np.ndarray) -> None:
    """A DOCK plan's checks (``plan_from_msg``; waypoints are bounded by ``_points``). A finite
    but huge load_direction overflows its norm to inf, which the unit check rejects: the
    overflow itself is not worth a RuntimeWarning."""
    if len(waypoints) < 2:
        raise MessageError(f"a DOCK plan needs >= 2 waypoints, got {len(waypoints)}")
    move = waypoints[-1] - waypoints[-2]
    length = np.linalg.norm(move)
    with np.errstate(over="ignore", invalid="ignore"):
        load_norm, along = np.linalg.norm(load), move @ load
    if length <= 0.0:
        raise MessageError("the loading move (last waypoint pair) has zero length")
    if not abs(load_norm - 1.0) <= UNIT_TOLERANCE:
        raise MessageError(f"load_direction must be a unit vector, got {load}")
    if not along >= (1.0 - UNIT_TOLERANCE) * length:
        raise MessageError(
            f"the loading move {move.tolist()} does not point along load_direction "
            f"{load.tolist()} (the executor pushes along the last waypoint pair)"
        )
    if scalars[0] <= 0 or scalars[1] <= 0:
        raise MessageError("contact_force_threshold and max_speed must be > 0")


def plan_from_msg(msg: DockingPlan) -> PlanCommand:
    """DockingPlan -> PlanCommand. A DOCK plan needs >= 2 distinct waypoints, a unit load along
    its last (loading) move, positive force threshold and speed; a GIVE_UP plan may have no
    waypoints."""
    if msg.decision not in (DockingPlan.DOCK, DockingPlan.GIVE_UP):
        raise MessageError(f"unknown decision {msg.decision}")
    dock = msg.decision == DockingPlan.DOCK
    waypoints = _points("waypoints", msg.waypoints, validate.MAX_WAYPOINTS)
    load = finite("load_direction", [msg.load_direction.x, msg.load_direction.y])
    scalars = finite(
        "thresholds", [msg.contact_force_threshold, msg.max_speed, msg.docking_probability]
    )
    if dock:
        _check_loading_move(waypoints, load, scalars)
    return PlanCommand(
        plan_id=int(msg.plan_id),
        dock=dock,
        waypoints=waypoints,
        load=load,
        force_threshold=float(scalars[0]),
        max_speed=float(scalars[1]),
        compliant=bool(msg.compliant),
        p_dock=float(scalars[2]),
        objective=float(msg.objective),
        target_edge=int(msg.target_edge),
        reason=msg.reason,
        target_point=np.array([msg.target_point.x, msg.target_point.y], float),
        episode=int(msg.episode),
        history_length=int(msg.history_length),
        nonce=int(msg.nonce),
    )


# --------------------------------------------------------------------------- execution reports


def report_to_msg(report: Report, header: Header) -> ExecutionReport:
    return ExecutionReport(
        header=header,
        episode=int(report.episode),
        plan_id=int(report.plan_id),
        nonce=int(report.nonce),
        outcome=int(report.outcome),
        segments=segments_to_msgs(report.history, header, report.plan_id),
        stop_point=plane_point(report.stop_point),
        detail=report.detail,
    )


def report_from_msg(msg: ExecutionReport) -> Report:
    if msg.outcome not in OUTCOMES:
        raise MessageError(f"unknown outcome {msg.outcome}")
    history = history_from_segments(msg.segments)
    if any(s.plan_id != msg.plan_id for s in msg.segments):
        raise MessageError(f"segments of plan {msg.plan_id}'s report carry another plan_id")
    return Report(
        plan_id=int(msg.plan_id),
        outcome=int(msg.outcome),
        history=history,
        stop_point=_points("stop_point", [msg.stop_point], 1)[0],
        detail=msg.detail,
        episode=int(msg.episode),
        nonce=int(msg.nonce),
    )


# --------------------------------------------------------------------------- episodes


def episode_from_msg(msg) -> int:
    """std_msgs/UInt32 on ``episode`` -> the episode id; 0 means "no episode" and is never sent."""
    if msg.data == 0:
        raise MessageError("episode id 0 is reserved (no episode)")
    return int(msg.data)


# EpisodeStatus.state constants by name (the planner's states); a cycle's outcome is an Outcome
# name, INTERRUPTED (the executor stopped it because the planner fell silent) or '' (no report).
EPISODE_STATES = ("IDLE", "RUNNING", "DOCKED", "GAVE_UP", "ABORTED", "CANCELED")
INTERRUPTED = "INTERRUPTED"
_STATE_NAMES = {getattr(EpisodeStatus, name): name for name in EPISODE_STATES}
_CYCLE_OUTCOMES = {
    "": EpisodeCycle.PENDING,
    INTERRUPTED: EpisodeCycle.INTERRUPTED,
    **{outcome.name: outcome.value for outcome in Outcome},
}
_CYCLE_OUTCOME_NAMES = {code: name for name, code in _CYCLE_OUTCOMES.items()}


def episode_status_to_msg(
    header: Header,
    state: str,
    episode: int,
    detail: str,
    prior_vertices: int,
    cycles,
    nonce: int = 0,
    hold_id: int = 0,
) -> EpisodeStatus:
    """The planner's episode status; ``state`` one of EPISODE_STATES, ``cycles`` its records in
    order (dicts: p_dock, inference_s, planning_s and, once reported, execution_s and outcome),
    ``nonce`` the episode's (0: none), ``hold_id`` and ``prior_vertices`` its hold's."""
    return EpisodeStatus(
        header=header,
        episode=int(episode),
        hold_id=int(hold_id),
        nonce=int(nonce),
        state=getattr(EpisodeStatus, state),
        detail=detail,
        prior_vertices=int(prior_vertices),
        cycles=[
            EpisodeCycle(
                docking_probability=float(c["p_dock"]),
                inference_time=float(c["inference_s"]),
                planning_time=float(c["planning_s"]),
                execution_time=float(c.get("execution_s", 0.0)),
                outcome=_CYCLE_OUTCOMES[c.get("outcome", "")],
            )
            for c in cycles
        ],
    )


def episode_status_from_msg(msg: EpisodeStatus) -> tuple[str, int]:
    """EpisodeStatus -> (state, one of EPISODE_STATES; episode id)."""
    if msg.state not in _STATE_NAMES:
        raise MessageError(f"unknown episode state {msg.state}")
    return _STATE_NAMES[msg.state], int(msg.episode)


def dock_feedback(state: str, cycles) -> Dock.Feedback:
    """The /dock action's feedback on the last of ``cycles`` (the planner's records, as
    ``episode_status_to_msg`` takes them, plus ``target``: the plan's aim point or None and,
    once reported, ``segments``: the evidence rows the attempt added)."""
    cycle = cycles[-1]
    return Dock.Feedback(
        cycle=len(cycles),
        state=getattr(EpisodeStatus, state),
        docking_probability=float(cycle["p_dock"]),
        target=plane_point((0.0, 0.0) if cycle.get("target") is None else cycle["target"]),
        outcome=_CYCLE_OUTCOMES[cycle.get("outcome", "")],
        segments=int(cycle.get("segments", 0)),
    )


def dock_result(
    state: str, episode: int, hold_id: int, cycles: int, reason: str, docked=None, load=None
):
    """The /dock action's result; ``docked``, ``load``: plane 2-vectors of a DOCKED episode (the
    report's stop point, the load direction), None otherwise (zero in the message)."""
    return Dock.Result(
        outcome=getattr(EpisodeStatus, state),
        episode=int(episode),
        hold_id=int(hold_id),
        cycles=int(cycles),
        docked_point=plane_point((0.0, 0.0) if docked is None else docked),
        load=Vector3() if load is None else Vector3(x=float(load[0]), y=float(load[1]), z=0.0),
        reason=reason,
    )


def episode_cycles_from_msg(msg: EpisodeStatus) -> list[dict]:
    """EpisodeStatus.cycles -> the records ``episode_status_to_msg`` took (execution_s None and
    outcome '' while a cycle has no report)."""
    validate.bounded("cycles count", len(msg.cycles), validate.MAX_CYCLES)
    records = []
    for c in msg.cycles:
        if c.outcome not in _CYCLE_OUTCOME_NAMES:
            raise MessageError(f"unknown cycle outcome {c.outcome}")
        values = finite("cycle", [c.docking_probability, c.inference_time, c.planning_time,
                                  c.execution_time])  # fmt: skip
        outcome = _CYCLE_OUTCOME_NAMES[c.outcome]
        records.append(
            {
                "p_dock": values[0],
                "inference_s": values[1],
                "planning_s": values[2],
                "execution_s": values[3] if outcome else None,
                "outcome": outcome,
            }
        )
    return records


# --------------------------------------------------------------------------- holds


def hold_evaluation_to_msg(hold_id: int, evaluation, header: Header) -> HoldEvaluation:
    """``core.holds.evaluate_hold``'s answer for a kept hold -> HoldEvaluation (found)."""
    dock = evaluation.decision == "dock"
    return HoldEvaluation(
        hold_id=int(hold_id),
        found=True,
        header=header,
        decision=HoldEvaluation.DOCK if dock else HoldEvaluation.GIVE_UP,
        site=plane_point(evaluation.site),
        target_edge=int(evaluation.target_edge),
        site_docking_probability=float(evaluation.site_p_dock),
        path_docking_probability=float(evaluation.path_p_dock),
        reason=evaluation.reason,
        compute_time=float(evaluation.seconds),
    )


def hold_not_evaluated_msg(hold_id: int, reason: str, header: Header | None = None):
    """A HoldEvaluation without a plan: a hold not kept (no ``header``: not found), or a kept
    one the planner could not take (GIVE_UP, no site)."""
    if header is None:
        return HoldEvaluation(hold_id=int(hold_id), found=False, reason=reason)
    return HoldEvaluation(
        hold_id=int(hold_id),
        found=True,
        header=header,
        decision=HoldEvaluation.GIVE_UP,
        site=Point(x=np.nan, y=np.nan),
        target_edge=-1,
        reason=reason,
    )


# --------------------------------------------------------------------------- depth camera


def depth_from_image(msg: Image) -> np.ndarray:
    """sensor_msgs/Image (16UC1 mm or 32FC1 m; step, byte order honoured) -> (h, w) metres,
    NaN where there is no return (``perception.depth.decode_depth``)."""
    validate.bounded("depth image width*height", msg.width * msg.height, validate.MAX_PIXELS)
    if len(msg.data) != msg.step * msg.height:
        raise MessageError(f"depth image data has {len(msg.data)} bytes, step*height is "
                           f"{msg.step * msg.height}")  # fmt: skip
    try:
        return depth_codec.decode_depth(
            msg.data, msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step
        )
    except PerceptionError as err:
        raise MessageError(f"depth image: {err}") from err


def intrinsics_from_camera_info(info: CameraInfo, image: Image | None = None) -> np.ndarray:
    """CameraInfo K (3, 3), checked against ``image``'s size and frame (default: the info's
    own, which checks K alone); distortion is not used."""
    image = info if image is None else image
    if not 0 < info.width * info.height <= validate.MAX_PIXELS:
        raise MessageError(f"camera info size {info.width}x{info.height} is out of range")
    if info.header.frame_id != image.header.frame_id:
        raise MessageError(
            f"camera info of frame {info.header.frame_id!r} for an image of "
            f"{image.header.frame_id!r}"
        )
    try:
        return depth_codec.check_intrinsics(
            info.k, image.height, image.width, info.height, info.width
        )
    except PerceptionError as err:
        raise MessageError(f"camera info: {err}") from err


def depth_to_image(depth_m: np.ndarray, header: Header, encoding: str = "32FC1") -> Image:
    data, step = depth_codec.encode_depth(depth_m, encoding)
    height, width = np.shape(depth_m)
    return Image(
        header=header, height=height, width=width, encoding=encoding, is_bigendian=False,
        step=step, data=data,
    )  # fmt: skip


def camera_info(K: np.ndarray, width: int, height: int, header: Header) -> CameraInfo:
    return CameraInfo(
        header=header, width=width, height=height, distortion_model="plumb_bob",
        d=[0.0] * 5, k=np.asarray(K, float).ravel().tolist(),
        r=np.eye(3).ravel().tolist(),
        p=np.hstack([np.asarray(K, float), np.zeros((3, 1))]).ravel().tolist(),
    )  # fmt: skip
