"""Run one docking episode against a running node suite and record it (make demo, tests).

:class:`EpisodeClient` is an rclpy node that listens to everything an episode produces (prior,
samples, history, plans, reports, the planner's ``episode_status``, the commands to the arm and
the mock ground truth), sends a goal to the planner's ``dock`` action and waits, bounded, for its
result. The record gives the action's feedback and result, the per-cycle progress lines, the
latency breakdown and the episode figure.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistStamped
from rclpy.action import ActionClient
from rclpy.node import Node

from tactile_dock_ros.action import Dock
from tactile_dock_ros.msg import (
    ContactHistory,
    DockingPlan,
    EpisodeStatus,
    ExecutionReport,
    SampleRequest,
    ShapeDistribution,
    ShapeSamples,
)
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.tools import bag, figures

FINAL_STATES = ("DOCKED", "GAVE_UP", "ABORTED", "CANCELED")


@dataclass
class EpisodeRecord:
    """Everything one episode published, as received."""

    prior: ShapeDistribution | None = None
    truth: ShapeDistribution | None = None
    perception_seconds: float | None = None
    samples: list = field(default_factory=list)
    history: ContactHistory | None = None
    plans: list = field(default_factory=list)
    reports: list = field(default_factory=list)
    requests: list = field(default_factory=list)  # the planner's sample requests (give-up check)
    status: EpisodeStatus | None = None
    feedback: list = field(default_factory=list)  # Dock.Feedback, as received
    result: Dock.Result | None = None
    goal_status: int | None = None  # the goal's final action_msgs/GoalStatus, with the result
    command_speeds: list = field(default_factory=list)  # m/s of every command to the arm
    wall_seconds: float = 0.0
    messages: list = field(default_factory=list)  # (topic, receive ns, msg) for tools.bag.write
    offered_qos: dict = field(default_factory=dict)  # bag topic -> its publishers' QoS profiles

    @property
    def state(self) -> str:
        """The goal's outcome once its result came, else the planner's latest state
        (``convert.EPISODE_STATES``); NONE before either."""
        if self.result is not None:
            return convert.EPISODE_STATES[self.result.outcome]
        return convert.episode_status_from_msg(self.status)[0] if self.status else "NONE"

    @property
    def detail(self) -> str:
        """Why the planner entered its latest state ('' if it did not say)."""
        return self.status.detail if self.status is not None else ""

    def cycles(self) -> list[dict]:
        """Per cycle: p_dock, decision, outcome ('-' without a report) and the latencies the
        planner recorded (None until it has)."""
        recorded = convert.episode_cycles_from_msg(self.status) if self.status else []
        out = []
        for i, plan in enumerate(self.plans, start=1):
            record = recorded[i - 1] if i <= len(recorded) else {}
            out.append(
                {
                    "cycle": i,
                    "p_dock": plan.docking_probability,
                    "decision": "DOCK" if plan.decision == DockingPlan.DOCK else "GIVE_UP",
                    "outcome": record.get("outcome") or "-",
                    **{
                        key: record.get(key) for key in ("inference_s", "planning_s", "execution_s")
                    },
                }
            )
        return out


class EpisodeClient(Node):
    """Listens to the suite; :meth:`run` sends one dock goal and waits for its result."""

    def __init__(self, **kwargs) -> None:
        super().__init__("episode_client", **kwargs)
        self.record = EpisodeRecord()
        self.printed = 0
        self.dock_client = ActionClient(self, Dock, "/dock")
        self.goal = None  # the accepted goal's ClientGoalHandle
        self.result = None  # its result Future
        keep = {
            attribute: lambda m, a=attribute: setattr(self.record, a, m)
            for attribute in ("prior", "truth", "history", "status")
        }
        subscriptions = [
            (ShapeDistribution, "/terrain_prior", keep["prior"], bag.QOS["/terrain_prior"]),
            (ShapeDistribution, "/mock_hardware/ground_truth", keep["truth"], qos.LATCHED),
            (ContactHistory, "/contact_history", keep["history"], qos.LATCHED),
            (EpisodeStatus, "/episode_status", keep["status"], qos.LATCHED),
            (ShapeSamples, "/shape_samples", self.record.samples.append, qos.LATCHED),
            (DockingPlan, "/plan", self.on_plan, qos.EVENTS),
            (ExecutionReport, "/execution_report", self.record.reports.append, qos.EVENTS),
            (SampleRequest, "/sample_request", self.record.requests.append, qos.EVENTS),
        ]
        for msg_type, topic, callback, profile in subscriptions:
            if topic in bag.EPISODE_TOPICS:
                callback = self._recorded(topic, callback)
            self.create_subscription(msg_type, topic, callback, profile)
        self.create_subscription(
            DiagnosticStatus, "/perception/status", self.on_perception, qos.LATCHED
        )
        self.create_subscription(TwistStamped, "/arm/cmd_twist", self.on_command, qos.COMMAND)

    def _recorded(self, topic: str, callback):
        """``callback`` that first logs the message for a bag, as ``ros2 bag record`` would."""

        def record(msg) -> None:
            self.record.messages.append((topic, self.get_clock().now().nanoseconds, msg))
            callback(msg)

        return record

    def on_plan(self, msg: DockingPlan) -> None:
        """Plans are resent until executed: keep one of each (plan_id, stamp)."""
        key = (msg.plan_id, msg.header.stamp.sec, msg.header.stamp.nanosec)
        if all(
            (p.plan_id, p.header.stamp.sec, p.header.stamp.nanosec) != key
            for p in self.record.plans
        ):
            self.record.plans.append(msg)

    def on_perception(self, msg: DiagnosticStatus) -> None:
        values = {kv.key: kv.value for kv in msg.values}
        self.record.perception_seconds = float(values.get("seconds", "nan"))

    def on_command(self, msg: TwistStamped) -> None:
        v = msg.twist.linear
        self.record.command_speeds.append(float(np.linalg.norm([v.x, v.y, v.z])))

    def spin_until(self, executor, done, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        return bool(done())

    def destroy_node(self) -> None:
        """rclpy's ``destroy_node`` leaves action clients alive (they are waitables)."""
        self.dock_client.destroy()
        super().destroy_node()

    def run(
        self, executor, timeout_s: float, progress=print, goal: Dock.Goal | None = None
    ) -> EpisodeRecord:
        """Wait for the suite (prior, action server, plan/report matches), send ``goal`` (None:
        the empty goal, the planner's parameters), wait for its result."""
        t0 = self.start(executor, timeout_s, goal)
        self.wait_result(executor, timeout_s, progress)
        self.record.wall_seconds = time.monotonic() - t0
        # Topics are not ordered with each other: let in-flight plans (the result counts
        # them), reports, the final status and the last feedback (sent at the end of an episode
        # that planned) arrive (bounded).
        docking = sum(p.decision == DockingPlan.DOCK for p in self.record.plans)
        feedback = self.record.feedback
        cycles = 0 if self.record.result is None else self.record.result.cycles
        self.spin_until(
            executor,
            lambda: (
                len(self.record.plans) >= cycles
                and len(self.record.reports) >= docking
                and self.status_state() == self.record.state
                and (
                    not self.record.plans
                    or (feedback and feedback[-1].state != EpisodeStatus.RUNNING)
                )
            ),
            5.0,
        )
        self._progress(progress)
        return self.record

    def status_state(self) -> str:
        """The planner's latest state on ``episode_status`` (NONE before any)."""
        status = self.record.status
        return convert.episode_status_from_msg(status)[0] if status else "NONE"

    def wait_result(self, executor, timeout_s: float, progress=print) -> bool:
        """Spin until the goal's result came (then in ``record.result``), printing a line per
        finished cycle; whether it came within ``timeout_s``."""

        def ended() -> bool:
            self._progress(progress)
            return self.result.done()

        if self.spin_until(executor, ended, timeout_s):
            response = self.result.result()
            self.record.result, self.record.goal_status = response.result, response.status
        return self.record.result is not None

    def start(self, executor, timeout_s: float, goal: Dock.Goal | None = None) -> float:
        """Wait for the suite, then send ``goal`` (None: the empty goal); the time.monotonic()
        of the send. RuntimeError when the planner rejects it (its log says why)."""
        ready = self.spin_until(
            executor,
            lambda: (
                self.record.prior is not None
                and self.record.status is not None
                and self.record.status.prior_vertices > 0  # the planner has it
                and self.dock_client.server_is_ready()
                and self.count_publishers("plan") > 0
                and self.count_publishers("execution_report") > 0
                and self.count_publishers("shape_samples") > 0
            ),
            timeout_s,
        )
        if not ready:
            raise TimeoutError("the node suite did not come up (prior, /dock, topics)")
        self.record.offered_qos = {  # as ros2 bag record stores them
            topic: [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            for topic in bag.EPISODE_TOPICS
        }
        t0 = time.monotonic()
        sent = self.dock_client.send_goal_async(
            goal or Dock.Goal(), feedback_callback=lambda m: self.record.feedback.append(m.feedback)
        )
        if not self.spin_until(executor, sent.done, 10.0):
            raise TimeoutError("no answer from /dock to the goal within 10 s")
        if not sent.result().accepted:
            raise RuntimeError("the planner rejected the dock goal (its log says why)")
        self.goal, self.result = sent.result(), sent.result().get_result_async()
        return t0

    def _progress(self, progress) -> None:
        cycles = [
            c
            for c in self.record.cycles()
            if c["planning_s"] is not None and (c["outcome"] != "-" or c["decision"] != "DOCK")
        ]
        for cycle in cycles[self.printed :]:
            progress(format_cycle(cycle))
        self.printed = max(self.printed, len(cycles))


def format_cycle(c: dict) -> str:
    def ms(key):
        return "-" if c[key] is None else f"{1000 * c[key]:.0f} ms"

    return (
        f"cycle {c['cycle']}: P_dock={c['p_dock']:.3f} decision={c['decision']} "
        f"outcome={c['outcome']}  (inference {ms('inference_s')}, planning {ms('planning_s')}, "
        f"execution {ms('execution_s')})"
    )


def latency_table(record: EpisodeRecord) -> str:
    """Median and max per stage over the cycles, plus perception and the episode wall time."""
    rows = []
    if record.perception_seconds is not None:
        rows.append(("perception (prior)", [record.perception_seconds]))
    for key, label in (("inference_s", "inference"), ("planning_s", "planning"),
                       ("execution_s", "execution")):  # fmt: skip
        values = [c[key] for c in record.cycles() if c[key] is not None]
        if values:
            rows.append((label, values))
    lines = [f"{'stage':<20} {'cycles':>6} {'median':>10} {'max':>10}"]
    for label, values in rows:
        lines.append(
            f"{label:<20} {len(values):>6} {np.median(values):>9.3f}s {np.max(values):>9.3f}s"
        )
    lines.append(f"{'episode wall time':<20} {'':>6} {record.wall_seconds:>9.3f}s")
    return "\n".join(lines)


def plot(record: EpisodeRecord, path: Path) -> None:
    """Episode figure: truth, prior mean, last posterior samples, history, planned paths."""
    plt = figures.pyplot()
    fig, ax = plt.subplots(figsize=(7, 6))
    if record.samples:
        for v in convert.samples_from_msg(record.samples[-1])[:30]:
            ax.plot(v[:, 0], v[:, 1], color=(0.2, 0.4, 1.0), alpha=0.15, lw=1)
    for msg, fmt, width, label in (
        (record.prior, "b--", 1, "prior mean"),
        (record.truth, "k-", 2, "ground truth"),
    ):
        if msg is not None:
            shape = convert.shape_from_msg(msg)
            figures.outline(ax, shape.mean_vertices, shape.closed, fmt, lw=width, label=label)
    for plan in record.plans:
        w = np.array([[p.x, p.y] for p in plan.waypoints]).reshape(-1, 2)
        ax.plot(w[:, 0], w[:, 1], ":", color="0.4", lw=1)
    if record.history is not None:
        figures.history(ax, convert.history_from_segments(record.history.segments), width=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"episode: {record.state} after {len(record.plans)} cycles")
    ax.legend(loc="best")
    figures.save(fig, path, dpi=120)
