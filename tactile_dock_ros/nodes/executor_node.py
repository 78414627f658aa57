"""executor: runs DockingPlans on the arm as guarded moves and reports what it felt.

Subscribes ``plan`` (DockingPlan), ``tool_pose`` (PoseStamped, base frame), ``wrench``
(WrenchStamped, F/T sensor, in the base frame or the tool frame: ``wrench_frame``) and the
planner's ``episode_status`` (EpisodeStatus: a plan of an episode that ended or was superseded
is stopped); the planner resends the plan being executed every 0.5 s: when no copy arrived for
``producer_timeout`` the planner is gone (crashed, killed) and the arm is stopped (ABORTED,
detail ``execution.types.PRODUCER_LOST``; a restarted planner replans);
publishes ``cmd_twist`` (TwistStamped, base frame) at the control rate while a plan runs, and
``execution_report`` (ExecutionReport, with the plan's episode and id) when it ends, and
``/diagnostics`` (DiagnosticArray, every ``diagnostics_period``: ``nodes.diagnostics``). Messages
in an unexpected frame are dropped with an error (tf2 is not used). The state machine and the
safety checks (the force limit on the whole 3-D force, out-of-plane pushes included) are in
``execution.guarded``, the sensor watch and the episode admission of plans in ``nodes.watchdog``;
this file is the ROS glue. The control loop runs on a thread of its own
(``nodes.control_thread``, SCHED_FIFO at ``thread_priority``), so that no subscription's
deserialization or callback delays a command; it and the callbacks share the node's state
under one lock. An ABORTED report carries no segments: what an aborted attempt felt
is not evidence (a stale sensor or a stopped plan may have misread it).

A managed (lifecycle) node, as ros2_control's and nav2's nodes that drive hardware: configure
validates the parameters (a bad value fails the transition: ``ValueError`` when autostarting)
and creates publishers, subscriptions and timers; activate starts the control loop; deactivate
stops the arm at once (zero command; a running or waiting plan is reported ABORTED, detail
``DEACTIVATED``) and plans are refused (report ``refused: executor inactive``) until activated
again; cleanup and shutdown send a zero command and release everything. ``autostart`` (default
true) configures and activates the node as it starts (``ros2 launch`` with a plain ``<node>``,
``tools.bringup``, in-process tests); false leaves it unconfigured for a lifecycle manager or
``ros2 lifecycle set /executor configure``. Decision: configure does not wait for the arm's
streams (bringup may configure before the drivers are up); it logs whether pose and wrench have
publishers, and a plan waits up to ``connect_timeout`` for their first samples, as before.
"""

from __future__ import annotations

import functools
import gc
import os
import sys
import threading
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from tactile_dock_ros.core.history import History
from tactile_dock_ros.execution.guarded import ForceFilter, GuardedRun, Limits, Settings
from tactile_dock_ros.execution.types import PRODUCER_LOST, Outcome, Report
from tactile_dock_ros.msg import DockingPlan, EpisodeStatus, ExecutionReport
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
from tactile_dock_ros.nodes.control_thread import ControlThread
from tactile_dock_ros.nodes.diagnostics import ExecutorHealth
from tactile_dock_ros.nodes.params import Param, declare
from tactile_dock_ros.nodes.watchdog import Admission, EpisodeGate


def _locked(method):
    """Run ``method`` holding the node's state lock: the control thread and the executor's
    callbacks share the plan, the sensor state, the filter and the publishers."""

    @functools.wraps(method)
    def holding_the_lock(self, *args, **kwargs):
        with self.lock:
            return method(self, *args, **kwargs)

    return holding_the_lock


def _tuning(name: str, *spec) -> Param:
    """A guarded-move setting whose default is guarded.Settings' (one source for both)."""
    return Param(name, getattr(Settings, name), *spec)


SEEN_PLANS = 64  # plan keys remembered to ignore resent copies
WATCHDOG_MARGIN_S = 0.001  # the watchdog tick comes this long after a stream's timeout
DEACTIVATED = "executor deactivated (lifecycle)"  # in the detail of a plan stopped by deactivate
INACTIVE = "refused: executor inactive"  # the detail of a plan received while not active


# Of the process, declared as the node starts: the rest are declared by configure.
NODE_PARAMS = [
    Param(
        "autostart",
        True,
        "configure and activate the node as it starts (false: wait for lifecycle transitions, "
        "e.g. ros2 lifecycle set /executor configure, then activate)",
    ),
    Param(
        "thread_priority",
        50,
        "SCHED_FIFO priority of the control loop's own thread (0: the normal scheduler; "
        "above 0 the callback thread also runs at nice -20); as ros2_control's controller "
        "manager: needs root or an rtprio limit, else a warning and the normal scheduler",
        "",
        0,
        99,
    ),
]

CONFIG_PARAMS = [
    *PLANE_TABLE,
    Param("control_rate_hz", 100.0, "guarded-move control rate", "Hz", 1.0, 1000.0),
    Param("max_speed", 0.1, "speed limit of any command", "m/s", 1e-4, 1.0),
    Param("max_force", 40.0, "contact force limit: abort above it", "N", 0.1, 500.0),
    Param("sensor_timeout", 0.5, "abort when pose or wrench is older than this", "s", 0.01, 10.0),
    Param(
        "connect_timeout",
        10.0,
        "a plan waits this long for the first pose and wrench",
        "s",
        0.01,
        600.0,
    ),
    *workspace_box([-1.0, -1.0], [1.0, 1.0], "workspace box"),
    _tuning("contact_resolution", "length of reported contact segments", "m", 1e-4, 0.1),
    _tuning("waypoint_tolerance", "a waypoint counts as reached within this", "m", 1e-5, 0.05),
    _tuning("slip_tolerance", "displacement under load that counts as slip", "m", 1e-5, 0.05),
    _tuning("load_speed", "pushing speed of the stick/slip test", "m/s", 1e-4, 1.0),
    _tuning("load_force", "loading test pushes up to this force", "N", 0.1, 500.0),
    _tuning("retreat_distance", "back-off after a failed contact", "m", 0.0, 0.2),
    _tuning("settle_time", "compliant slide: held this still under load = stuck", "s", 0.0, 10.0),
    _tuning("max_slide", "compliant slide: longer slides fail the attempt", "m", 0.0, 2.0),
    _tuning(
        "evidence_spacing",
        "compliant slide: one slip observation per this much of each crossed piece (a few of "
        "the prior's vertex spacings: core.slides.EVIDENCE_SPACING_M)",
        "m",
        1e-3,
        1.0,
    ),
    _tuning("slide_on_slip", "non-compliant plans: slide on after a slip, evidence only"),
    _tuning(
        "released_fraction",
        "after the retreat the tool moves along the force until it is below this fraction of "
        "the plan's contact threshold",
        "",
        0.01,
        1.0,
    ),
    _tuning("approach_gain", "speed = min(max, gain * distance to waypoint)", "1/s", 0.1, 100.0),
    Param(
        "wrench_frame",
        "base",
        "frame of the wrench: base = base_frame_id; tool = the F/T sensor's frame, aligned with "
        "the tool_pose orientation (rotated into the base frame with it)",
        choices=("base", "tool"),
    ),
    Param("filter_cutoff_hz", 20.0, "F/T low-pass cutoff", "Hz", 0.1, 1000.0),
    Param("bias_samples", 10, "F/T readings averaged for the bias at each plan start", "", 1, 1000),
    Param(
        "producer_timeout",
        4.0,
        "stop the arm when no copy of the running plan (resent every 0.5 s) came for this long",
        "s",
        1.5,
        60.0,
    ),
    Param("diagnostics_period", 1.0, "period of the /diagnostics status", "s", 0.05, 60.0),
]
PARAMS = [*CONFIG_PARAMS, *NODE_PARAMS]
SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


class ExecutorNode(LifecycleNode):
    def __init__(self, **kwargs) -> None:
        super().__init__("executor", **kwargs)
        self.node_params = declare(self, NODE_PARAMS)  # ValueError: not started at all
        self.p = None  # the configured parameters (None: unconfigured)
        self.active = False  # plans run only while active
        self.config_error = ""
        self.cmd_pub = None
        self.entities: list = []  # what configure created and cleanup destroys
        self.lock = threading.RLock()  # see _locked
        self.sensor_lock = threading.Lock()  # the latest pose and the force filter
        self.control: ControlThread | None = None  # the control loop, while active
        self.control_fault: BaseException | None = None
        self.fault_guard = self.create_guard_condition(self.raise_control_fault)
        if self.node_params.autostart:
            self.start()

    def start(self) -> None:
        """configure + activate now (``autostart``); a failed configure raises ValueError."""
        if self.trigger_configure() != SUCCESS:
            raise ValueError(self.config_error or "executor: configure failed")
        if self.trigger_activate() != SUCCESS:
            raise RuntimeError("executor: activate failed")

    # ---------------------------------------------------------------- lifecycle

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Validate the parameters (FAILURE names the bad one), then create publishers,
        subscriptions and timers (the control timer stays cancelled until activate)."""
        try:
            self.p = p = declare(self, PARAMS)
            if np.any(np.asarray(p.workspace_min) >= np.asarray(p.workspace_max)):
                raise ValueError("parameter workspace_min must be below workspace_max")
        except ValueError as err:
            self.p, self.config_error = None, str(err)
            self.get_logger().error(f"configure failed: {err}")
            return FAILURE
        self.configure_from(p)
        self.report_streams("configured")
        return SUCCESS

    def configure_from(self, p) -> None:
        self.plane = plane_frame(p)
        self.limits = Limits(
            np.asarray(p.workspace_min),
            np.asarray(p.workspace_max),
            p.max_speed,
            p.max_force,
            p.sensor_timeout,
        )
        self.settings = Settings(
            contact_resolution=p.contact_resolution,
            waypoint_tolerance=p.waypoint_tolerance,
            slip_tolerance=p.slip_tolerance,
            load_force=p.load_force,
            load_speed=p.load_speed,
            retreat_distance=p.retreat_distance,
            settle_time=p.settle_time,
            max_slide=p.max_slide,
            evidence_spacing=p.evidence_spacing,
            slide_on_slip=p.slide_on_slip,
            released_fraction=p.released_fraction,
            approach_gain=p.approach_gain,
        )
        self.filter = ForceFilter(p.filter_cutoff_hz, p.bias_samples)
        self.dt = 1.0 / p.control_rate_hz
        self.tool: np.ndarray | None = None
        self.tool_rotation = np.eye(3)  # tool frame -> base frame, from the latest pose
        self.health = ExecutorHealth(p.sensor_timeout, self.dt)
        # monotonic arrival (s) of each stream's newest sample: the control thread's watchdog
        self.arrived = {"tool_pose": -np.inf, "wrench": -np.inf}
        self.gate = EpisodeGate()
        self.run: GuardedRun | None = None
        self.pending = None  # (plan, time received) waiting for a tool pose
        # (plan_id, stamp) already handled, oldest first; only the last SEEN_PLANS are kept
        # (copies of a plan arrive while it runs and shortly after; older ones meet the gate)
        self.seen_plans: dict[tuple[int, int, int], None] = {}
        self.last_plan = (0, 0)  # (episode, plan_id) of the newest plan accepted
        self.plan_heard = (None, 0.0)  # (key, node-clock s) of the newest copy of the run plan
        # Plain publishers, not lifecycle ones: the zero command must go out in every state
        # (deactivate, cleanup, exit) and refusals are reported while inactive; nothing but
        # the control timer, cancelled while inactive, commands a motion.
        self.cmd_pub = self.create_publisher(TwistStamped, "cmd_twist", qos.COMMAND)
        self.report_pub = self.create_publisher(ExecutionReport, "execution_report", qos.REPORTS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", qos.EVENTS)
        plane_id, base_id = p.plane_frame_id, p.base_frame_id
        wrench_id = base_id if p.wrench_frame == "base" else None  # else the sensor's frame
        self.stream_subs = {
            "tool_pose": subscribe(
                self, PoseStamped, "tool_pose", self.on_pose, qos.SENSOR, base_id
            ),
            "wrench": subscribe(
                self, WrenchStamped, "wrench", self.on_wrench, qos.SENSOR, wrench_id
            ),
        }
        self.entities = [
            *self.stream_subs.values(),
            subscribe(self, DockingPlan, "plan", self.on_plan, qos.EVENTS, plane_id),
            subscribe(self, EpisodeStatus, "episode_status", self.on_episode_status, qos.LATCHED),
            self.create_timer(p.diagnostics_period, self.publish_diagnostics),
            self.cmd_pub,
            self.report_pub,
            self.diagnostics_pub,
        ]

    def report_streams(self, what: str) -> None:
        """Log whether the arm's pose and wrench streams have publishers and samples; a warning,
        not a failure, when not (drivers may start later: plans wait ``connect_timeout``)."""
        parts, missing = [], []
        for stream, sub in self.stream_subs.items():
            publishers = self.count_publishers(sub.topic_name)
            heard = self.health.streams[stream].last is not None
            parts.append(f"{sub.topic_name}: {publishers} publishers, samples {heard}")
            if not (publishers and heard):
                missing.append(stream)
        text = f"{what}; {'; '.join(parts)}"
        if missing:
            self.get_logger().warning(
                f"{text}: {' and '.join(missing)} not flowing yet (a plan waits up to "
                f"connect_timeout {self.p.connect_timeout} s for them)"
            )
        else:
            self.get_logger().info(text)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Accept plans and start the control loop on its own thread (``ControlThread``)."""
        with self.lock:
            self.active = True
        self.control = ControlThread(
            self.on_tick,
            self.dt,
            self.node_params.thread_priority,
            self.log_priority,
            self.on_control_fault,
            self.watchdog_deadline,
        )
        self.control.start()
        self.report_streams("active")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the arm now: a running plan is aborted (reported, no segments), a waiting one
        reported, a zero command sent in this callback; then refuse plans until activated."""
        with self.lock:
            self.active = False  # a tick from here on commands nothing
            self.stop(DEACTIVATED)
        self.stop_control()
        return super().on_deactivate(state)

    def stop_control(self) -> None:
        """End the control thread (its last tick finishes first; idempotent)."""
        if self.control is not None:
            self.control.stop(timeout_s=10 * self.dt + 1.0)
            self.control = None

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.release()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState | None = None) -> TransitionCallbackReturn:
        """Two callers. The lifecycle shutdown transition (``state`` given): stop and release.
        ``common.run`` as the process exits (no ``state``: SIGINT, SIGTERM, an exception in a
        callback): command zero and wait up to SHUTDOWN_ACK_S for the arm to acknowledge it, as
        a driver would otherwise go on with the last command until its own timeout."""
        if state is not None:
            self.release()
            return super().on_shutdown(state)
        self.stop_control()
        if self.cmd_pub is not None:
            with self.lock:
                self.command(np.zeros(2))
            self.cmd_pub.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_S))
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """A transition raised: stop the arm and release; the node is unconfigured after it."""
        self.release()
        return SUCCESS

    def stop(self, why: str) -> None:
        """Abort a running plan and drop a waiting one (each reported ABORTED), command zero."""
        if self.run is not None:
            if not self.run.done:
                self.run.abort(f"stopped: {why}", self.tool)
            self.command(np.zeros(2))
            self.end_run(now_seconds(self))
        elif self.pending is not None:
            plan, self.pending = self.pending[0], None
            self.report(plan, Outcome.ABORTED, f"stopped before starting: {why}")
        self.command(np.zeros(2))

    def release(self) -> None:
        """End the control loop, command zero, then destroy what configure created
        (idempotent)."""
        with self.lock:
            self.active = False
        self.stop_control()
        if self.cmd_pub is None:
            return
        with self.lock:
            self.stop("executor released (lifecycle)")
        for entity in self.entities:
            if hasattr(entity, "cancel"):
                self.destroy_timer(entity)
            elif hasattr(entity, "publish"):
                self.destroy_publisher(entity)
            else:
                self.destroy_subscription(entity)
        self.entities, self.cmd_pub, self.p = [], None, None

    # ---------------------------------------------------------------- topics

    # The sensor callbacks take only ``sensor_lock`` (for microseconds), not the node's lock:
    # at the streams' rates a thread that takes a lock again and again keeps a waiting thread
    # from it (measured: 12 % of the control ticks late by more than a period with the sensors
    # at 10x while the callbacks held the node's lock).

    def on_pose(self, msg: PoseStamped) -> None:
        tool = convert.pose_position(msg, self.plane)
        rotation = None
        if self.p.wrench_frame == "tool":  # the rotation is computed only when it is used
            rotation = convert.pose_rotation(msg)
        else:  # but a NaN orientation is malformed input all the same
            convert.pose_orientation(msg)
        with self.sensor_lock:
            if rotation is not None:
                self.tool_rotation = rotation
            self.tool = tool
        self.arrived["tool_pose"] = time.monotonic()
        self.health.streams["tool_pose"].add(now_seconds(self))

    def on_wrench(self, msg: WrenchStamped) -> None:
        """Filter the force in the frame it comes in (the sensor bias is constant there); a
        force above the limit stops a running plan now, not at the next tick."""
        force = convert.wrench_force(msg)
        now = now_seconds(self)
        self.arrived["wrench"] = time.monotonic()
        self.health.streams["wrench"].add(now)
        with self.sensor_lock:
            self.filter.add(now, force)
            total = float(np.linalg.norm(self.base_force())) if self.filter.ready else 0.0
        if total > self.limits.max_force:
            with self.lock:
                run = self.run
                if run is not None and not run.done:
                    run.abort(f"force {total:.1f} N (3-D) above the limit", self.tool)
                    self.command(np.zeros(2))
                    self.end_run(now)

    def base_force(self) -> np.ndarray:
        """Bias-free filtered force (3,) newtons in the base frame (hold ``sensor_lock``)."""
        if self.p.wrench_frame == "tool":
            return self.tool_rotation @ self.filter.value
        return self.filter.value

    @_locked
    def on_plan(self, msg: DockingPlan) -> None:
        """Run, refuse (with a report; every DOCK plan while the node is inactive) or drop
        (MessageError: no report) a plan. Decision: a refused or dropped plan changes no state -
        neither the plan order (``last_plan``) nor the running plan's heartbeat (it is marked
        seen: its copies are not refused again); the running plan's copies are recognised
        before the bounded ``seen_plans`` is consulted, so no other traffic evicts them."""
        plan = convert.plan_from_msg(msg)  # first: a malformed copy must not mark a plan seen
        key = (msg.plan_id, msg.header.stamp.sec, msg.header.stamp.nanosec)
        if key == self.plan_heard[0]:  # the planner resends a plan until its report arrives
            self.plan_heard = (key, now_seconds(self))
            return
        if key in self.seen_plans:
            return
        if not self.gate.authentic(plan.episode, plan.nonce):
            raise convert.MessageError(
                f"plan {plan.plan_id} of episode {plan.episode} without the episode's nonce "
                "(not sent by the planner)"
            )
        admission, why = self.gate.admit(plan.episode)
        if admission is Admission.WAIT:  # not marked seen: a copy after the status may run
            raise convert.MessageError(f"plan {plan.plan_id} of episode {plan.episode}: {why}")
        self.check_order(plan)
        self.seen_plans[key] = None
        if len(self.seen_plans) > SEEN_PLANS:
            del self.seen_plans[next(iter(self.seen_plans))]
        if not plan.dock:
            self.last_plan = (plan.episode, plan.plan_id)
            self.get_logger().info(f"plan {plan.plan_id}: GIVE_UP ({plan.reason}); nothing to run")
            return
        if not self.active:  # deactivated: nothing moves until activated again
            self.report(plan, Outcome.ABORTED, INACTIVE)
            return
        if self.busy():  # a second plan is refused, never preempts the running one
            self.report(plan, Outcome.ABORTED, "refused: another plan is running")
            return
        if admission is Admission.REFUSE:
            self.report(plan, Outcome.ABORTED, f"refused: {why}")
            return
        self.last_plan = (plan.episode, plan.plan_id)
        self.pending = (plan, now_seconds(self))
        self.plan_heard = (key, now_seconds(self))  # its copies: the planner lives
        self.get_logger().info(
            f"plan {plan.plan_id}: {len(plan.waypoints)} waypoints, P_dock={plan.p_dock:.3f}"
        )

    def busy(self) -> bool:
        return self.run is not None or self.pending is not None

    def check_order(self, plan) -> None:
        """Plans of one episode run in plan-id order: a plan not after the last one accepted
        (late or replayed) is dropped (no report); which episodes may run at all is
        ``EpisodeGate``'s decision."""
        if self.last_plan[0] == plan.episode and plan.plan_id <= self.last_plan[1]:
            raise convert.MessageError(
                f"plan {plan.plan_id} of episode {plan.episode} after its plan {self.last_plan[1]}"
            )

    @_locked
    def on_episode_status(self, msg: EpisodeStatus) -> None:
        """Stop a plan whose episode is over (the planner aborted or gave up) or superseded."""
        state, episode = convert.episode_status_from_msg(msg)
        self.gate.update(episode, state, int(msg.nonce))
        plan = self.run.plan if self.run else self.pending[0] if self.pending else None
        if plan is None or (plan.episode == episode and state == "RUNNING"):
            return
        why = f"episode {episode} is {state}" if plan.episode == episode else "a new episode began"
        if self.run is not None:
            if not self.run.done:  # on_tick stops the arm and reports
                self.run.abort(f"stopped: {why}", self.tool)
        else:
            self.pending = None
            self.report(plan, Outcome.ABORTED, f"stopped before starting: {why}")

    def start_pending(self) -> None:
        """Start the received plan while its episode runs (``EpisodeGate``: refused once it
        ended or was superseded) and pose and wrench flow: fresh (within sensor_timeout) if they
        ever arrived, else waiting up to connect_timeout for the first ones (discovery)."""
        plan, received = self.pending
        now = now_seconds(self)
        admission, why = self.gate.admit(plan.episode)
        if admission is not Admission.RUN:
            self.pending = None
            self.report(plan, Outcome.ABORTED, f"refused: {why}")
            return
        stamps = [w.last for w in self.health.streams.values()]
        if all(s is not None and now - s <= self.limits.sensor_timeout for s in stamps):
            self.pending = None
            with self.sensor_lock:
                self.filter.reset()
            self.run = GuardedRun(plan, self.tool, self.limits, self.settings, now)
            self.health.counts["plans_run"] += not self.run.done
            return
        never = any(s is None for s in stamps)
        if now - received > (self.p.connect_timeout if never else self.limits.sensor_timeout):
            self.pending = None
            missing = [n for n, s in zip(("tool pose", "wrench"), stamps, strict=True) if s is None]
            why = f"no {' or '.join(missing)} received" if missing else "sensor data too old"
            self.command(np.zeros(2))
            self.report(plan, Outcome.ABORTED, f"sensor timeout: {why}")

    def watchdog_deadline(self) -> float | None:
        """Monotonic time (s) a running plan's older stream times out (``ControlThread``
        ticks then, not at the next period), plus ``WATCHDOG_MARGIN_S`` so that the tick's
        node-clock age is past ``sensor_timeout``; None with no plan running."""
        run = self.run  # read without the node lock: a stale answer costs one extra tick
        if run is None or run.done:
            return None
        return min(self.arrived.values()) + self.limits.sensor_timeout + WATCHDOG_MARGIN_S

    @_locked
    def on_tick(self) -> None:
        """One control period (the control thread): watch the producer, start a waiting plan,
        step the running one and command its velocity; nothing while inactive."""
        if not self.active:
            return
        self.health.tick(now_seconds(self))
        silent = now_seconds(self) - self.plan_heard[1]
        if silent > self.p.producer_timeout and self.busy():
            why = f"{PRODUCER_LOST} no copy of the plan for {silent:.1f} s"
            if self.run is not None and not self.run.done:
                self.run.abort(why, self.tool)  # stopped and reported below
            elif self.pending is not None:
                plan, self.pending = self.pending[0], None
                self.report(plan, Outcome.ABORTED, why)
        if self.pending is not None:
            self.start_pending()
        run = self.run
        if run is None:
            return
        t = now_seconds(self)
        stream, age = self.health.oldest(t)
        velocity = np.zeros(2)
        with self.sensor_lock:  # None: the F/T bias is being estimated at rest
            force = self.base_force() if self.filter.ready else None
        if not run.done and age > self.limits.sensor_timeout:  # the stop within one tick
            run.abort(f"sensor timeout: {stream} {age:.2f} s old", self.tool)
        elif not run.done and force is not None:
            in_plane = self.plane.vector_to_plane(force)
            normal = float(np.sqrt(max(force @ force - in_plane @ in_plane, 0.0)))
            velocity = run.step(t, self.tool, in_plane, age, normal_force=normal)
            velocity = run.check_next(self.tool, velocity, self.dt)
        self.command(velocity)
        if run.done:
            self.end_run(t)

    def end_run(self, t: float) -> None:
        """Report the finished run (the arm was just commanded to stop) and forget it."""
        run, self.run = self.run, None
        self.report(run.plan, run.outcome, run.detail, run.history, run.stop_point)
        self.get_logger().info(
            f"plan {run.plan.plan_id}: outcome={run.outcome.name} ({run.detail}); "
            f"{len(run.history)} segments, {t - run.t_start:.2f} s, "
            f"max commanded speed {run.max_speed_commanded:.3f} m/s"
        )

    def command(self, velocity: np.ndarray) -> None:
        v3 = self.plane.vector_from_plane(velocity)
        self.cmd_pub.publish(convert.twist_to_msg(v3, header(self, self.p.base_frame_id)))

    @_locked
    def publish_diagnostics(self) -> None:
        if not self.active:
            state = "inactive (plans refused)"
        elif self.run is not None:
            state = f"running plan {self.run.plan.plan_id}"
        elif self.pending is not None:
            state = f"plan {self.pending[0].plan_id} waiting to start"
        else:
            state = "idle"
        gate = self.gate
        episode = (
            "any"
            if gate.current is None
            else f"{gate.current} " + ("RUNNING" if gate.running else "over")
        )
        status = self.health.status(now_seconds(self), self.get_name(), state, {"episode": episode})
        self.diagnostics_pub.publish(
            DiagnosticArray(header=header(self, self.p.base_frame_id), status=[status])
        )

    def report(self, plan, outcome, detail, history=None, stop_point=None) -> None:
        """Publish the plan's report. ABORTED: no segments (not evidence), and counted in the
        diagnostics as refused (detail ``refused: ...``, nothing moved) or as a fault."""
        stop = self.tool if stop_point is None else stop_point
        if outcome is Outcome.ABORTED:
            if history is not None and len(history):
                detail += f" ({len(history)} segments discarded)"
            history = None
            refused = detail.startswith("refused")
            self.health.counts["plans_refused" if refused else "plans_aborted"] += 1
            if not refused:
                self.health.fault(now_seconds(self), f"plan {plan.plan_id}: {detail}")
        report = Report(
            episode=plan.episode,
            plan_id=plan.plan_id,
            nonce=plan.nonce,
            outcome=outcome.value,
            history=History() if history is None else history,
            stop_point=np.zeros(2) if stop is None else stop,
            detail=detail,
        )
        self.report_pub.publish(convert.report_to_msg(report, header(self, self.p.plane_frame_id)))
        if outcome is Outcome.ABORTED:
            self.get_logger().warning(f"plan {plan.plan_id}: ABORTED: {detail}")

    def log_priority(self, refused: OSError | None) -> None:
        """``thread_priority`` (SCHED_FIFO) of the control thread: set, or refused and why.
        Decision: under CPU load the normal scheduler woke the control loop late (dropout stop
        p99 65 ms, one 513 ms stall at load 5 on 2 cores); a SCHED_FIFO thread is woken when
        its period ends. It waits between ticks, so it does not starve the machine."""
        priority = self.node_params.thread_priority
        if refused is None:
            self.get_logger().info(f"control loop thread: SCHED_FIFO priority {priority}")
            return
        self.get_logger().warning(
            f"thread_priority {priority}: real-time scheduling refused ({refused}); the control "
            "loop runs with the normal scheduler (grant rtprio, e.g. limits.conf, or set 0)"
        )

    def before_spin(self) -> None:
        """The thread that spins the node (``common.run``: takes the samples and plans) runs
        with nice ``CALLBACK_NICE`` (when ``thread_priority`` > 0) and the GIL is handed over
        every ``GIL_SWITCH_S``. Decision: the control thread needs the GIL, so the thread that
        holds it must not stall: at the normal priority it was preempted by any busy process
        while holding it (a priority inversion: control ticks 15 ms late at the median beside
        4 CPU burners); as SCHED_FIFO, with the sensors at 10x it used a whole core and the
        kernel's real-time throttling (``sched_rt_runtime_us``) stopped it, and with it the
        control thread, for up to 100 ms. A high-weight normal thread is neither preempted for
        long nor throttled. The switch interval is 0.1 ms: a thread that waits for the GIL
        asks the holder to drop it only after a whole interval without a release, and the
        callback thread, taking 1 kHz of samples, released and re-took it every few tenths of
        a millisecond, so with 1 ms the control thread waited up to 400 ms (ticks late by more
        than a period: 5.9 % at 1 ms, none at 0.1 ms, sensors at 10x on an idle machine). The
        objects that exist by now (modules, the node) are moved out of
        the garbage collector's reach (``gc.freeze``): a full collection of them held the GIL
        for 28 ms (more on a loaded machine) whichever thread ran it."""
        gc.freeze()
        sys.setswitchinterval(GIL_SWITCH_S)
        if self.node_params.thread_priority == 0:
            return
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), CALLBACK_NICE)
        except (OSError, AttributeError) as err:  # reported by the control thread
            self.get_logger().debug(f"callback thread nice {CALLBACK_NICE} refused: {err}")

    def on_control_fault(self, err: BaseException) -> None:
        """An exception in a tick (the control thread): stop the arm, then raise it in the
        thread that spins the node (``raise_control_fault``), which exits as any callback's
        exception does (``common.run``: zero command, clean up)."""
        self.control_fault = err
        self.get_logger().error(f"control loop failed: {err!r}")
        with self.lock:
            self.active = False
            self.command(np.zeros(2))
        self.fault_guard.trigger()

    def raise_control_fault(self) -> None:
        if self.control_fault is not None:
            raise self.control_fault

    def destroy_node(self) -> None:
        """Destroy the node with its control thread and its lifecycle state machine.
        Decision: rclpy's LifecycleNode keeps the state machine, which holds the node handle,
        until the object is collected, so a destroyed executor stayed in the ROS graph (a second
        'executor' that queries by name found first: the fuzz check saw none of its
        subscriptions)."""
        self.stop_control()
        super().destroy_node()
        self._state_machine.destroy_when_not_in_use()


CALLBACK_NICE = -20  # the nice value of the thread that runs the callbacks (before_spin)
# sys.setswitchinterval of the executor process (Python's default: 5 ms); see before_spin
GIL_SWITCH_S = 0.0001
SHUTDOWN_ACK_S = 0.5  # exit waits this long at most for the arm to acknowledge the stop


def main(args: list[str] | None = None) -> int:
    return run(ExecutorNode, args)
