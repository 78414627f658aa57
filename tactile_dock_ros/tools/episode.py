"""Run one docking episode against a running node suite and record it (make demo, tests).

:class:`EpisodeClient` is an rclpy node that listens to everything an episode produces (prior,
samples, history, plans, reports, the planner's ``episode_status``, the commands to the arm and
the mock ground truth), calls ``start_episode`` and waits, bounded, for the end. The record
gives the per-cycle progress lines, the latency breakdown and the episode figure.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from tactile_dock_ros.msg import (
    ContactHistory,
    DockingPlan,
    EpisodeStatus,
    ExecutionReport,
    ShapeDistribution,
    ShapeSamples,
)
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.tools import bag, figures

FINAL_STATES = ("DOCKED", "GAVE_UP", "ABORTED")


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
    status: EpisodeStatus | None = None
    command_speeds: list = field(default_factory=list)  # m/s of every command to the arm
    wall_seconds: float = 0.0
    messages: list = field(default_factory=list)  # (topic, receive ns, msg) for tools.bag.write
    offered_qos: dict = field(default_factory=dict)  # bag topic -> its publishers' QoS profiles

    @property
    def state(self) -> str:
        """The planner's latest state (``convert.EPISODE_STATES``), NONE before any status."""
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
    """Listens to the suite; :meth:`run` starts one episode and waits for its end."""

    def __init__(self, **kwargs) -> None:
        super().__init__("episode_client", **kwargs)
        self.record = EpisodeRecord()
        self.printed = 0
        self.start_client = self.create_client(Trigger, "start_episode")
        keep = {
            attribute: lambda m, a=attribute: setattr(self.record, a, m)
            for attribute in ("prior", "truth", "history", "status")
        }
        subscriptions = [
            (ShapeDistribution, "/terrain_prior", keep["prior"], qos.LATCHED),
            (ShapeDistribution, "/mock_hardware/ground_truth", keep["truth"], qos.LATCHED),
            (ContactHistory, "/contact_history", keep["history"], qos.LATCHED),
            (EpisodeStatus, "/episode_status", keep["status"], qos.LATCHED),
            (ShapeSamples, "/shape_samples", self.record.samples.append, qos.LATCHED),
            (DockingPlan, "/plan", self.on_plan, qos.EVENTS),
            (ExecutionReport, "/execution_report", self.record.reports.append, qos.EVENTS),
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

    def run(self, executor, timeout_s: float, progress=print) -> EpisodeRecord:
        """Wait for the suite (prior, service, plan/report matches), start, wait for the end."""
        t0 = self.start(executor, timeout_s)
        self.spin_until(executor, lambda: self._progress(progress) in FINAL_STATES, timeout_s)
        self.record.wall_seconds = time.monotonic() - t0
        # Topics are not ordered with each other: let in-flight reports arrive (bounded).
        docking = sum(p.decision == DockingPlan.DOCK for p in self.record.plans)
        self.spin_until(executor, lambda: len(self.record.reports) >= docking, 5.0)
        return self.record

    def start(self, executor, timeout_s: float) -> float:
        """Wait for the suite, then start an episode; the time.monotonic() of the start."""
        ready = self.spin_until(
            executor,
            lambda: (
                self.record.prior is not None
                and self.record.status is not None
                and self.record.status.prior_vertices > 0  # the planner has it
                and self.start_client.service_is_ready()
                and self.count_publishers("plan") > 0
                and self.count_publishers("execution_report") > 0
                and self.count_publishers("shape_samples") > 0
            ),
            timeout_s,
        )
        if not ready:
            raise TimeoutError("the node suite did not come up (prior, start_episode, topics)")
        self.record.offered_qos = {  # as ros2 bag record stores them
            topic: [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
            for topic in bag.EPISODE_TOPICS
        }
        t0 = time.monotonic()
        future = self.start_client.call_async(Trigger.Request())
        self.spin_until(executor, future.done, 10.0)
        if not future.done() or not future.result().success:
            raise RuntimeError(f"start_episode failed: {future.result() if future.done() else ''}")
        return t0

    def _progress(self, progress) -> str:
        cycles = [
            c
            for c in self.record.cycles()
            if c["planning_s"] is not None and (c["outcome"] != "-" or c["decision"] != "DOCK")
        ]
        for cycle in cycles[self.printed :]:
            progress(format_cycle(cycle))
        self.printed = max(self.printed, len(cycles))
        return self.record.state


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
