"""planner: docking plans from posterior samples (paper Sec. V-B), and the episode loop.

An episode starts with a goal of the ``dock`` action (``Dock.action``: the hold to dock on,
overrides of max_cycles, give_up_threshold and compliant for this episode; feedback at each plan
and report; the result),
or with the ``start_episode`` service (std_srvs/Trigger), a thin wrapper kept for simple scripts
that starts the same episode as an empty goal. Both are refused while an episode runs or before a
``terrain_prior`` arrived, a goal also when a field is out of range (the reason is logged; a
refused goal or call changes nothing). Decisions: the planner serves the action because it owns
the episode (its id, cycles, budget and end); a second goal is rejected, not preempting (the arm
may be mid-move on the first: a caller that wants another hold cancels first); cancel ends the
episode CANCELED, the executor stops the arm as for any episode that leaves RUNNING and inference
keeps the history. The node publishes a new id on ``episode`` (latched), which empties
inference's history. The id is the node clock's milliseconds at the start, mod 2^32, so a
restarted planner never reuses one; plans carry it, and reports of other episodes (a late report, a
restarted node) are ignored. Each cycle it waits for ``shape_samples`` conditioned on the whole
current ``contact_history`` (stamped after the episode start) and the tool position (``tool_pose``),
calls ``core.planner.plan`` and publishes a ``plan`` (DockingPlan). What it plans on is one
``core.episode.EpisodeState`` (the history with each row's plan id, the tool position, the aim
points of the episode's plans) and one ``PlannerConfig`` (the parameters and the goal's
overrides, mapped by ``planner_config``). The executor's ``execution_report`` ends the cycle. The
episode ends DOCKED (a report says so), GAVE_UP (the planner's decision, or ``max_cycles`` reports
without docking), ABORTED (the executor aborted) or CANCELED. ``episode_status`` (EpisodeStatus,
latched) carries the state, the prior's vertex count (0: none yet) and each cycle's P_dock,
latencies and outcome.

Holds: the node keeps each ``terrain_prior`` it receives by its ``hold_id`` (perception's capture
id; ``core.holds.ReceivedPriors``, the last ``max_holds`` as perception keeps them) and the
latest; a goal's ``hold_id`` (0: the latest) picks the episode's prior, pinned for the episode (a
capture meanwhile does not change it), an id not kept is rejected. Decision: inference keeps the
priors by id the same way and samples on the hold that ``episode_status`` names (``hold_id``),
its samples say which hold they were drawn from (``ShapeSamples.hold_id``) and the planner plans
only on samples of its episode's hold, so the two cannot plan and sample on different priors.
Asking perception to republish the chosen hold instead would add a service call and a wait state
to goal handling and still leave inference racing the new prior against the episode start.
``terrain_prior`` is latched with the last ``max_holds`` (``qos.priors``): a node started after
several captures receives every hold perception keeps, oldest first and the latest last, so it
docks on, or resumes an episode on, any of them; a replayed prior costs a conversion and, while
idle, an ``episode_status`` (planning waits for samples).

Restart without loss: with ``state_directory`` set, the episode's events (start with the goal's
settings and hold, each plan with its serialized message, each report's outcome, the end) go to a
journal (``nodes.journal``, ``<state_directory>/planner.jsonl``, replaced at each start). A
restarted planner replays it: the same episode id (republished, so inference keeps its history),
settings, hold, cycles, aim points (eq. 24) and the plan being executed, which it resends again
(the action goal does not survive a restart: its client watches ``episode_status``); a RUNNING
episode whose last event is older than ``resume_timeout`` (wall clock) is not resumed but ends
ABORTED. An attempt
the executor stopped because this node fell silent (``Report.producer_lost``) ends its cycle
without ending the episode: the next plan is made once inference has the attempt's evidence.

Give-up check: a give-up after a contact on fewer than ``give_up_samples`` samples is not
published; the node asks inference for that many samples of the same history
(``sample_request``, SampleRequest with the episode's nonce, once per history length), plans
again on the first set of that history with more samples than it had and gives up only if that
plan does (``core.episode_posterior``'s docstring: a give-up read off ~100 samples misses paths
of P_dock ~0.01). When no answer came within ``sample_request_timeout`` the give-up stands on
the samples it had (an inference node that does not draw on, or was restarted, cannot keep the
episode waiting); the bench loop does the same (``core.explore.run_episode``'s
``give_up_samples``).
"""

from __future__ import annotations

import base64
import dataclasses
import secrets
import time

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.task import Future
from rclpy.time import Time
from std_msgs.msg import UInt32
from std_srvs.srv import Trigger

from tactile_dock_ros.action import Dock
from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.holds import ReceivedPriors
from tactile_dock_ros.core.planner import plan as plan_docking
from tactile_dock_ros.execution.types import PlanCommand
from tactile_dock_ros.msg import (
    ContactHistory,
    DockingPlan,
    EpisodeStatus,
    ExecutionReport,
    SampleRequest,
    ShapeDistribution,
    ShapeSamples,
)
from tactile_dock_ros.nodes import convert, journal, qos, validate
from tactile_dock_ros.nodes.common import (
    LOAD_DIRECTION,
    MAX_HOLDS,
    PLANE_TABLE,
    Stopwatch,
    header,
    now_seconds,
    plane_frame,
    run,
    stamp_seconds,
    subscribe,
    unit_load,
    workspace_box,
)
from tactile_dock_ros.nodes.params import Param, declare

PARAMS = [
    *PLANE_TABLE,
    LOAD_DIRECTION,
    Param("give_up_threshold", 1e-3, "give up below this docking probability", "", 0.0, 1.0),
    Param("contact_resolution", 0.01, "exploration-bonus width w of eq. (24)", "m", 1e-4, 0.1),
    Param("contact_force_threshold", 3.0, "guarded-move stop force", "N", 0.01, 500.0),
    Param("max_speed", 0.1, "tool speed along the path", "m/s", 1e-4, 1.0),
    Param("compliant", False, "plan with the compliant motion model"),
    *workspace_box([-1.0, -1.0], [1.0, 1.0], "executor's box (no path leaves it)"),
    Param(
        "max_slide",
        PlannerConfig.max_slide,
        "executor's max_slide: how far an unreported slide can carry the tool from its moves "
        "(the step back to them reaches this + 0.05 m)",
        "m",
        0.0,
        2.0,
    ),
    Param(
        "give_up_samples",
        0,
        "a give-up after a contact on fewer posterior samples asks inference to draw on to this "
        "many (sample_request) and plans again; 0: off (docs/nodes.md: 400 and its cost)",
        "",
        0,
        100000,
    ),
    Param(
        "sample_request_timeout",
        10.0,
        "wait this long for the answer of a sample_request, then give up on the samples at "
        "hand; below stage_timeout",
        "s",
        0.1,
        600.0,
    ),
    Param("max_cycles", 10, "cycle budget of an episode (GAVE_UP after it)", "", 1, 1000),
    Param("stage_timeout", 120.0, "ABORT when samples or a report take longer", "s", 1.0, 3600.0),
    MAX_HOLDS,
    Param("state_directory", "", "directory of the crash-safe episode journal; empty: none"),
    Param(
        "resume_timeout",
        120.0,
        "a restart resumes a running episode whose last event is at most this old",
        "s",
        0.0,
        86400.0,
    ),
]


GOAL_OVERRIDES = ("max_cycles", "give_up_threshold", "compliant")  # Dock goal fields
# the parameters planner_config maps (perception and tools.replay declare and read the same)
CONFIG_SETTINGS = (
    "load_direction", "give_up_threshold", "contact_resolution", "compliant", "workspace_min",
    "workspace_max", "max_slide",
)  # fmt: skip


def planner_config(p) -> PlannerConfig:
    """The planner parameters (``PARAMS`` values, by attribute) as ``core.planner`` settings:
    the one mapping, shared with ``tools.replay``."""
    return PlannerConfig(
        load=unit_load(p),
        contact_resolution=p.contact_resolution,
        give_up_threshold=p.give_up_threshold,
        compliant=p.compliant,
        workspace=(tuple(p.workspace_min), tuple(p.workspace_max)),
        max_slide=p.max_slide,
    )


def goal_settings(goal: Dock.Goal, p) -> dict:
    """The episode settings (``GOAL_OVERRIDES`` names -> values) of a dock goal: its nonzero
    fields, checked against the ranges of the parameters they override (``PARAMS``), else the
    parameters ``p`` (the node checks ``hold_id``: it keeps the holds). ValueError with the
    reason for a goal the planner must reject.
    Decision: 0 selects the parameter, so the empty goal runs the node's episode; NaN is
    refused like any non-finite value (a give_up_threshold of 0, never giving up, is only
    available as the parameter)."""
    settings = {name: getattr(p, name) for name in GOAL_OVERRIDES}
    table = {param.name: param for param in PARAMS}
    for name in ("max_cycles", "give_up_threshold"):
        value = getattr(goal, name)
        if value != 0:  # NaN included
            try:
                table[name].check(value)
            except ValueError as err:
                raise ValueError(f"override of the {err}") from None
            settings[name] = value
    if goal.compliant > Dock.Goal.NON_COMPLIANT:
        raise ValueError(f"compliant {goal.compliant} is not a COMPLIANT_* constant of the goal")
    if goal.compliant != Dock.Goal.COMPLIANT_DEFAULT:
        settings["compliant"] = goal.compliant == Dock.Goal.COMPLIANT
    return settings


def new_nonce() -> int:
    """A random nonzero 63-bit episode nonce (``watchdog.EpisodeGate.authentic``). Decision:
    from the operating system's entropy, not a seeded generator: it must differ between
    planners and restarts that share a seed, and nothing computed depends on its value."""
    return secrets.randbits(63) or 1


RESEND_PERIOD = 0.5  # seconds between copies of the plan being executed (executor heartbeat)
RUNNING, DOCKED, GAVE_UP, ABORTED, IDLE = "RUNNING", "DOCKED", "GAVE_UP", "ABORTED", "IDLE"
CANCELED = "CANCELED"


@dataclasses.dataclass
class PendingRequest:
    """A sample request of the give-up check (module docstring): its episode, history rows,
    node-clock seconds sent, the samples of the set it asked about, and whether it is over
    (answered with more samples, or timed out)."""

    episode: int
    rows: int
    sent_s: float
    samples: int
    answered: bool = False

    def asked_about(self, node) -> bool:
        """Whether it is of ``node``'s current episode and history."""
        return (self.episode, self.rows) == (node.episode, len(node.episode_state.history))


class PlannerNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("planner", **kwargs)
        self.p = declare(self, PARAMS)
        if self.p.give_up_samples and self.p.sample_request_timeout >= self.p.stage_timeout:
            raise ValueError(
                f"parameter sample_request_timeout ({self.p.sample_request_timeout:g} s) must be "
                f"below stage_timeout ({self.p.stage_timeout:g} s) with give_up_samples on: "
                "the stage timeout would abort the episode first"
            )
        self.configure(goal_settings(Dock.Goal(), self.p))
        self.plane = plane_frame(self.p)
        self.priors = ReceivedPriors(self.p.max_holds)
        self.hold_id = 0  # the running (or last) episode's hold: ``prior``
        # history with each row's plan (from contact_history), tool (tool_pose), aim points
        self.episode_state = EpisodeState()
        self.samples = None  # (msg, vertices) of the newest samples
        self.samples_ahead = None  # newer ones conditioned on rows not yet in contact_history
        self.episode = 0
        self.nonce = 0  # the episode's (new_nonce); its plans carry it, its reports must
        self.state = IDLE
        self.awaiting_plan = None  # plan_id being executed
        self.cycles: list[dict] = []
        self.episode_start = None
        self.goal = None  # the dock goal of the running episode (None: start_episode, resumed)
        self.goal_ends: dict[bytes, Future] = {}  # goal id -> (state, Dock.Result), by finish
        self.plan_pub = self.create_publisher(DockingPlan, "plan", qos.EVENTS)
        self.episode_pub = self.create_publisher(UInt32, "episode", qos.LATCHED)
        self.status_pub = self.create_publisher(EpisodeStatus, "episode_status", qos.LATCHED)
        self.request_pub = self.create_publisher(SampleRequest, "sample_request", qos.EVENTS)
        self.request: PendingRequest | None = None  # the give-up check's, the latest
        plane_id, base_id = self.p.plane_frame_id, self.p.base_frame_id
        priors = qos.priors(self.p.max_holds)
        subscriptions = [
            (ShapeDistribution, "terrain_prior", self.on_prior, priors, plane_id),
            (ContactHistory, "contact_history", self.on_history, qos.LATCHED, plane_id),
            (ShapeSamples, "shape_samples", self.on_samples, qos.LATCHED, plane_id),
            (ExecutionReport, "execution_report", self.on_report, qos.REPORTS, plane_id),
            (PoseStamped, "tool_pose", self.on_pose, qos.SENSOR, base_id),
        ]
        for subscription in subscriptions:
            subscribe(self, *subscription)
        self.create_service(Trigger, "start_episode", self.on_start)
        ActionServer(
            self,
            Dock,
            "dock",
            execute_callback=self.execute_dock,
            goal_callback=self.on_goal,
            handle_accepted_callback=self.on_goal_accepted,
            cancel_callback=self.on_cancel,
        )
        self.create_timer(RESEND_PERIOD / 2, self.on_timer)
        self.last_plan = None  # (msg, node-clock seconds when last sent)
        self.stage_start = None  # node-clock seconds when the current wait began
        self.journal = journal.for_node(self.p.state_directory, "planner")
        self.publish_status(self.resume() if self.journal is not None else "")

    # ------------------------------------------------------------------ inputs

    @property
    def prior(self):
        """The prior planning uses: the running episode's hold's, else the latest (what a ``{}``
        goal docks on); None when it has not been received."""
        hold = self.priors.resolve(self.hold_id if self.state == RUNNING else 0)
        return None if hold is None else hold.prior

    def on_prior(self, msg: ShapeDistribution) -> None:
        prior = convert.shape_from_msg(msg)
        first = self.priors.latest is None
        stamp = Time.from_msg(msg.header.stamp).nanoseconds
        for note in self.priors.receive(msg.hold_id, stamp, prior):
            self.get_logger().info(note)
        for slot in ("samples", "samples_ahead"):  # kept unchecked until a prior came
            held = getattr(self, slot)
            try:
                if held is not None:
                    self.check_samples(*held)
            except convert.MessageError as err:
                setattr(self, slot, None)
                self.get_logger().warning(f"samples dropped: {err}")
        if self.state != RUNNING or first:
            self.publish_status()  # the latest hold (a goal of {} docks on it), or the first

    def on_pose(self, msg: PoseStamped) -> None:
        self.episode_state = self.episode_state.move(convert.pose_position(msg, self.plane))
        self.maybe_plan()

    def on_history(self, msg: ContactHistory) -> None:
        self.episode_state = convert.history_from_msg(msg, self.episode_state)
        ahead = self.samples_ahead
        if ahead is not None and ahead[0].history_length <= len(self.episode_state.history):
            self.samples, self.samples_ahead = ahead, None
        self.maybe_plan()

    def on_samples(self, msg: ShapeSamples) -> None:
        """Keep checked samples (``check_samples``; a refused message changes nothing). Samples
        conditioned on more rows than the known history wait aside until that history arrives
        (the two latched topics may arrive in either order, e.g. at a restart): they replace
        neither the current samples nor are dropped."""
        if msg.hold_id != self.hold_id and self.state == RUNNING:
            return  # drawn from another hold's prior: inference has not switched yet
        empty = msg.num_samples == 0 and len(msg.samples) == 0  # inference found no shape
        samples = (msg, None if empty else convert.samples_from_msg(msg))
        self.check_samples(*samples)
        if msg.history_length > len(self.episode_state.history):
            self.samples_ahead = samples
            return
        self.samples = samples
        if self.awaiting_answer() and msg.history_length == self.request.rows:
            # the answer has more samples than the set asked about; another set of the same
            # history (a resample) is planned on once the answer or the timeout comes
            self.request.answered = msg.num_samples > self.request.samples
        self.maybe_plan()

    def check_samples(self, msg: ShapeSamples, vertices) -> None:
        """MessageError unless the samples fit the prior (``validate.samples_fit_prior``: its
        vertex count, within 100 prior std of its mean). Before the prior has come they are
        kept unchecked: ``on_prior`` checks them then, and nothing plans without a prior."""
        if self.prior is not None:
            validate.samples_fit_prior(
                vertices, msg.num_vertices, self.prior.mean, self.prior.basis
            )

    # ------------------------------------------------------------------ starting an episode

    def refusal(self, goal: Dock.Goal) -> tuple[str, dict | None]:
        """('' and the episode settings, with its ``hold_id``: the goal's, 0 resolved to the
        latest prior's) when ``goal`` may start an episode now, else (why, None). Changes
        nothing."""
        if self.state == RUNNING:
            return f"episode {self.episode} is running", None
        if self.priors.latest is None:
            return "no terrain_prior yet (robot profile: call /perception/capture)", None
        hold = self.priors.resolve(goal.hold_id)
        if hold is None:
            kept = self.priors.holds.ids()
            return f"hold_id {goal.hold_id}: no such hold received (kept: {kept})", None
        try:
            return "", goal_settings(goal, self.p) | {"hold_id": hold.hold_id}
        except ValueError as err:
            return str(err), None

    def on_start(self, request, response):
        """start_episode: the episode of an empty dock goal, without feedback or result."""
        why, settings = self.refusal(Dock.Goal())
        if settings is None:
            self.get_logger().warning(f"start_episode refused: {why}")
            response.success, response.message = False, why
            return response
        self.start(settings)
        response.success, response.message = True, f"episode {self.episode} started"
        return response

    def on_goal(self, goal: Dock.Goal) -> GoalResponse:
        why, settings = self.refusal(goal)
        if settings is None:
            self.get_logger().warning(f"dock goal rejected: {why}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def on_goal_accepted(self, goal_handle) -> None:
        """Start the goal's episode. rclpy calls this right after ``on_goal`` accepted, in the
        same callback: no other goal or start_episode call can come in between."""
        self.start(self.refusal(goal_handle.request)[1])
        self.goal = goal_handle
        self.goal_ends[bytes(goal_handle.goal_id.uuid)] = Future()
        goal_handle.execute()

    async def execute_dock(self, goal_handle) -> Dock.Result:
        """Wait for ``finish``; the goal SUCCEEDS when DOCKED, is CANCELED when canceled and
        ABORTS otherwise (GAVE_UP, ABORTED: the result's outcome says which)."""
        key = bytes(goal_handle.goal_id.uuid)
        state, result = await self.goal_ends[key]
        del self.goal_ends[key]
        if state == DOCKED:
            goal_handle.succeed()
        elif goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return result

    def on_cancel(self, goal_handle) -> CancelResponse:
        """Cancel: the episode ends CANCELED at once (``finish``), so the executor stops the arm
        on the status; a goal whose episode already ended cannot be canceled."""
        if goal_handle is not self.goal or self.state != RUNNING:
            return CancelResponse.REJECT
        self.get_logger().info(f"episode {self.episode}: cancel requested by the dock client")
        self.finish(CANCELED, "canceled by the dock action client")
        return CancelResponse.ACCEPT

    def start(self, settings: dict) -> None:
        """Start an episode with ``settings`` (``goal_settings``)."""
        stamp_ms = (self.get_clock().now().nanoseconds // 1_000_000) % 2**32
        self.episode = stamp_ms if stamp_ms not in (0, self.episode) else self.episode + 1
        self.state, self.cycles, self.nonce = RUNNING, [], new_nonce()
        self.hold_id = settings["hold_id"]
        self.configure(settings)
        self.episode_state = EpisodeState(tool=self.episode_state.tool)  # inference clears too
        self.awaiting_plan = None
        self.episode_start = self.get_clock().now()
        self.stage_start = now_seconds(self)
        start = {"event": "start", "episode": self.episode, "nonce": self.nonce}
        start |= {"start_ns": self.episode_start.nanoseconds, "settings": settings}
        self.log(start, reset=True)
        self.episode_pub.publish(UInt32(data=self.episode))
        self.get_logger().info(
            f"episode {self.episode}: started on hold {self.hold_id} ({settings})"
        )
        self.publish_status()

    def configure(self, settings: dict) -> None:
        """Plan with ``settings`` (``refusal``'s): ``self.settings``, ``self.config``."""
        self.settings = settings
        self.config = dataclasses.replace(
            planner_config(self.p),
            give_up_threshold=settings["give_up_threshold"],
            compliant=settings["compliant"],
        )

    def on_report(self, msg: ExecutionReport) -> None:
        report = convert.report_from_msg(msg)
        current = report.episode == self.episode and report.plan_id == self.awaiting_plan
        if self.state != RUNNING or not current:
            return
        if report.nonce != self.nonce:
            raise convert.MessageError(
                f"report of plan {report.plan_id} without the episode's nonce (not the executor's "
                "report of the plan sent)"
            )
        execution_s = stamp_seconds(msg.header.stamp) - self.cycles[-1]["plan_stamp"]
        event = {"event": "report", "plan_id": report.plan_id, "outcome": report.outcome_name}
        event |= {"execution_s": execution_s, "segments": len(report.history)}
        self.log(event | {"producer_lost": report.producer_lost})
        self.end_cycle(event, report.producer_lost)
        cycle = self.cycles[-1]
        self.get_logger().info(
            f"episode {self.episode} cycle {len(self.cycles)}: P_dock={cycle['p_dock']:.3f} "
            f"decision=DOCK outcome={report.outcome_name} ({report.detail})"
        )
        if report.outcome == ExecutionReport.DOCKED:
            self.finish(DOCKED, report.detail, docked=report.stop_point)
        elif report.outcome == ExecutionReport.ABORTED and not report.producer_lost:
            self.finish(ABORTED, report.detail)
        elif len(self.cycles) >= self.settings["max_cycles"]:
            self.finish(GAVE_UP, f"cycle budget of {self.settings['max_cycles']} spent")
        else:
            self.stage_start = now_seconds(self)
            self.publish_status()
            self.maybe_plan()

    # ------------------------------------------------------------------ planning

    def on_timer(self) -> None:
        """Resend the plan being executed every RESEND_PERIOD until its report arrives (an
        executor that matched late still gets it; to the executor the copies say that this node
        lives: it stops the arm when they stop), and abort an episode that waits longer than
        stage_timeout for samples or a report."""
        if self.state != RUNNING:
            return
        if self.awaiting_answer() and now_seconds(self) - self.request.sent_s > (
            self.p.sample_request_timeout
        ):
            self.get_logger().warning(
                f"episode {self.episode}: no answer to the sample request within "
                f"{self.p.sample_request_timeout:g} s; the give-up stands on the samples at hand"
            )
            self.request.answered = True
            self.maybe_plan()
            return
        if (
            self.awaiting_plan is not None
            and now_seconds(self) - self.last_plan[1] >= RESEND_PERIOD
        ):
            self.plan_pub.publish(self.last_plan[0])
            self.last_plan = (self.last_plan[0], now_seconds(self))
        if now_seconds(self) - self.stage_start <= self.p.stage_timeout:
            return
        waiting = "execution report" if self.awaiting_plan is not None else "posterior samples"
        self.finish(ABORTED, f"no {waiting} within {self.p.stage_timeout:.0f} s")

    def awaiting_answer(self) -> bool:
        """Whether a sample request of the current history is unanswered."""
        request = self.request
        return request is not None and not request.answered and request.asked_about(self)

    def ask_for_samples(self, count: int) -> bool:
        """Before a give-up on ``count`` samples after a contact: ask inference for
        ``give_up_samples`` (once per history); False when that is not wanted or was done."""
        rows, wanted = len(self.episode_state.history), self.p.give_up_samples
        asked = self.request is not None and self.request.asked_about(self)
        if rows == 0 or count >= wanted or asked:
            return False
        msg, _ = self.samples
        self.request_pub.publish(
            convert.sample_request_to_msg(
                header(self, ""), self.episode, self.nonce, msg.hold_id, rows, wanted
            )
        )
        self.request = PendingRequest(self.episode, rows, now_seconds(self), count)
        self.get_logger().info(
            f"episode {self.episode} cycle {len(self.cycles) + 1}: give-up on {count} samples; "
            f"asked inference for {wanted} of the {rows} history rows"
        )
        return True

    def ready(self) -> bool:
        if self.state != RUNNING or self.awaiting_plan is not None or self.samples is None:
            return False
        if self.awaiting_answer():
            return False
        msg, _ = self.samples
        fresh = Time.from_msg(msg.header.stamp) >= self.episode_start
        return (
            fresh
            and msg.hold_id == self.hold_id
            and self.prior is not None
            and self.episode_state.tool is not None
            and msg.history_length == len(self.episode_state.history)
            # the last report's evidence is in
            and msg.history_length >= (self.cycles[-1]["next_history"] if self.cycles else 0)
        )

    def maybe_plan(self) -> None:
        if not self.ready():
            return
        msg, vertices = self.samples
        if vertices is None:
            self.get_logger().info(
                f"episode {self.episode} cycle {len(self.cycles) + 1}: P_dock=0 decision=GIVE_UP "
                "outcome=- (no shape is consistent with the contact history)"
            )
            self.finish(GAVE_UP, "inference found no shape consistent with the contact history")
            return
        with Stopwatch() as watch:
            try:
                result = self.plan(vertices, msg.dropped_segments)
            except (ValueError, RuntimeError) as err:
                self.get_logger().error(f"planning failed: {err}")
                self.finish(ABORTED, f"planner failed: {err}")
                return
        if result.rejected:
            message = f"{result.rejected} of {len(vertices)} samples contradict a recorded slide"
            if result.rejected >= len(vertices) - 1:  # core.planner.plan kept them all
                self.get_logger().warning(f"{message}; fewer than two left, planned on all")
            else:
                self.get_logger().info(message)
        dock = result.decision == "dock"
        if not dock and self.ask_for_samples(len(vertices)):
            self.stage_start = now_seconds(self)
            return
        history_length = len(self.episode_state.history)
        command = PlanCommand(
            plan_id=len(self.cycles) + 1,
            dock=dock,
            # A give-up carries the tool position alone, so a recorded plan is self-contained.
            waypoints=np.asarray(result.path if dock else self.episode_state.tool).reshape(-1, 2),
            load=np.asarray(self.config.load),
            force_threshold=self.p.contact_force_threshold,
            max_speed=self.p.max_speed,
            compliant=self.config.compliant,
            p_dock=result.p_dock,
            objective=result.objective,
            target_edge=result.target_edge if dock else -1,
            reason=result.reason,
            target_point=result.target_point,
            episode=self.episode,
            history_length=history_length,
            nonce=self.nonce,
        )
        out = convert.plan_to_msg(command, header(self, self.p.plane_frame_id))
        event = {
            "event": "plan",
            "history_length": history_length,
            "p_dock": float(result.p_dock),
            "inference_s": float(msg.compute_time),
            "planning_s": watch.seconds,
            "plan_stamp": stamp_seconds(out.header.stamp),
            "dock": dock,
            "target": np.asarray(result.target_point, float).tolist() if dock else None,
            "msg": base64.b64encode(serialize_message(out)).decode(),
        }
        self.log(event)  # on disk before the executor can act on it
        self.add_cycle(event)
        self.plan_pub.publish(out)
        if not dock:
            self.get_logger().info(
                f"episode {self.episode} cycle {len(self.cycles)}: P_dock={result.p_dock:.3g} "
                f"decision=GIVE_UP outcome=- ({result.reason})"
            )
            self.finish(GAVE_UP, result.reason)
            return
        self.stage_start = now_seconds(self)
        self.publish_status()

    # ------------------------------------------------------------------ episode journal

    def add_cycle(self, event: dict) -> None:
        """Record a published plan (``event``: its journal record)."""
        keys = ("p_dock", "inference_s", "planning_s", "plan_stamp", "history_length")
        cycle = {key: event[key] for key in keys} | {"outcome": "", "target": event["target"]}
        cycle["next_history"] = event["history_length"] + 1  # the next plan needs its evidence
        self.cycles.append(cycle)
        if event["dock"]:
            out = deserialize_message(base64.b64decode(event["msg"]), DockingPlan)
            self.awaiting_plan = out.plan_id
            self.last_plan = (out, now_seconds(self))
            self.episode_state = self.episode_state.aim(event["target"])  # eq. (24) novelty

    def end_cycle(self, event: dict, interrupted: bool) -> None:
        """Record the report of the plan being executed (``event``: its journal record)."""
        cycle = self.cycles[-1]
        cycle["outcome"] = "INTERRUPTED" if interrupted else event["outcome"]
        cycle["execution_s"] = event["execution_s"]
        cycle["segments"] = event["segments"]
        if interrupted:  # plan again on the same history plus what the attempt felt
            cycle["next_history"] = cycle["history_length"] + event["segments"]
        self.awaiting_plan = None

    def log(self, event: dict, reset: bool = False) -> None:
        if self.journal is None:
            return
        event = event | {"wall_time": time.time()}
        try:
            self.journal.reset([event]) if reset else self.journal.append(event)
        except journal.JournalError as err:  # go on: the episode is still in memory
            self.get_logger().error(f"journal: {err}; a restart would lose this episode")

    def resume(self) -> str:
        """Replay the journal of the last episode; resume it when it was running. Returns the
        message of the first episode status."""
        records = self.journal.records
        if not records or records[0].get("event") != "start":
            return ""
        try:
            for event in records:
                self.replay(event)
        except (KeyError, TypeError, ValueError, IndexError) as err:
            self.get_logger().error(f"{self.journal.path}: bad record ({err}); not resumed")
            self.state, self.episode, self.cycles = IDLE, 0, []
            self.episode_state = EpisodeState(tool=self.episode_state.tool)
            self.awaiting_plan = None
            return ""
        if self.state != RUNNING:
            return ""
        age = time.time() - records[-1].get("wall_time", 0.0)
        if age > self.p.resume_timeout:
            why = f"not resumed: its last event is {age:.0f} s old"
            self.state, self.awaiting_plan = ABORTED, None
            self.log({"event": "finish", "state": ABORTED, "why": why})
            self.get_logger().warning(f"episode {self.episode}: {why}")
            return why
        self.stage_start = now_seconds(self)
        self.episode_pub.publish(UInt32(data=self.episode))
        waiting = f"plan {self.awaiting_plan}" if self.awaiting_plan else "samples"
        self.get_logger().warning(
            f"episode {self.episode}: resumed after a restart ({len(self.cycles)} cycles, "
            f"waiting for {waiting})"
        )
        return "resumed after a restart"

    def replay(self, event: dict) -> None:
        kind = event["event"]
        if kind == "start":
            self.episode, self.state, self.cycles = event["episode"], RUNNING, []
            self.nonce = int(event.get("nonce", 0))  # 0: a journal written before nonces
            # no settings: a journal written before dock goals; no hold: before hold ids
            settings = {"hold_id": 0} | (
                event.get("settings") or goal_settings(Dock.Goal(), self.p)
            )
            self.hold_id = settings["hold_id"]
            self.configure(settings)
            self.episode_state = EpisodeState(tool=self.episode_state.tool)
            clock_type = self.get_clock().clock_type
            self.episode_start = Time(nanoseconds=event["start_ns"], clock_type=clock_type)
        elif kind == "plan":
            self.add_cycle(event)
        elif kind == "report":
            self.end_cycle(event, event["producer_lost"])
        elif kind == "finish":
            self.state = event["state"]

    def plan(self, vertices: np.ndarray, dropped=()):
        """``core.planner.plan`` on the node's state; ``dropped``: the history rows inference
        ignored (ShapeSamples.dropped_segments)."""
        state = self.episode_state.sampled(dropped=dropped)
        return plan_docking(vertices, self.prior, state, self.config)

    def destroy_node(self) -> None:
        """rclpy's ``destroy_node`` leaves action servers alive (they are waitables). Also
        called by the context on a node whose constructor failed: no attribute is relied on."""
        for server in [w for w in self.waitables if isinstance(w, ActionServer)]:
            server.destroy()
        super().destroy_node()

    # ------------------------------------------------------------------ episode status

    def finish(self, state: str, why: str, docked=None) -> None:
        """End the episode in ``state``; ``docked``: the plane point of a DOCKED report."""
        self.state = state
        self.log({"event": "finish", "state": state, "why": why})
        self.get_logger().info(f"episode {self.episode}: {state} after {len(self.cycles)} cycles")
        self.publish_status(why)
        if self.goal is not None:
            load = None if docked is None else self.config.load
            result = convert.dock_result(
                state, self.episode, self.hold_id, len(self.cycles), why, docked, load
            )
            self.goal_ends[bytes(self.goal.goal_id.uuid)].set_result((state, result))
            self.goal = None

    def publish_status(self, detail: str = "") -> None:
        """Publish ``episode_status``, and the feedback of a dock goal's cycle (each change of
        a cycle: its plan, its report, the end)."""
        if self.goal is not None and self.cycles:
            self.goal.publish_feedback(convert.dock_feedback(self.state, self.cycles))
        prior = self.prior
        hold = self.hold_id if self.state == RUNNING else getattr(self.priors.latest, "hold_id", 0)
        self.status_pub.publish(
            convert.episode_status_to_msg(
                header(self, ""),
                self.state,
                self.episode,
                detail,
                0 if prior is None else prior.n_vertices,
                self.cycles,
                self.nonce,
                hold,
            )
        )


def main(args: list[str] | None = None) -> int:
    return run(PlannerNode, args)
