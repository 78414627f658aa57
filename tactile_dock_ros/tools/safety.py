"""Fault injection against the executor on the mock arm (dropout, envelope, load, exit).

:func:`mock_floor` starts ``executor`` and ``mock_hardware`` from the mock launch file as
processes (a flat floor, parameters of ``config/mock.yaml`` plus overrides) and a :class:`Probe`
node that plays the planner (plans, ``episode_status``), records every command to the arm, the
sensor streams, the reports and ``/diagnostics``, and stops the mock's sensor streams through its
``~/drop_wrench`` / ``~/drop_pose`` services. The scenario functions return plain dicts; the
tests assert on them and ``bench safety`` turns them into the README's figures.

Times: command and sensor header stamps are the publishing node's clock (one machine, one
system clock), so the dropout latency and the control-loop period are measured from stamps,
free of the probe's own scheduling.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription_content_filter_options import ContentFilterOptions
from std_srvs.srv import SetBool

from tactile_dock_ros.execution.types import PlanCommand, PlaneFrame, Report
from tactile_dock_ros.msg import DockingPlan, EpisodeStatus, ExecutionReport
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.nodes.common import stamp_seconds
from tactile_dock_ros.nodes.planner_node import RESEND_PERIOD
from tactile_dock_ros.tools import bringup

CONFIG = bringup.PACKAGE_ROOT / "config" / "mock.yaml"
FLOOR_END = 0.6  # the floor y = 0 spans |x| <= FLOOR_END; the mock workspace box is wider
FLOOR = {"vertices": [[FLOOR_END, 0.0], [-FLOOR_END, 0.0]], "start": [0.0, 0.3], "friction": 0.5}
COMMAND, POSE, WRENCH = "/arm/cmd_twist", "/arm/tool_pose", "/ft_sensor/wrench"
STREAM_TOPICS = {"wrench": WRENCH, "pose": POSE}


def percentiles(values, qs=(50, 99)) -> dict[str, float]:
    """{'p50': ..., 'p99': ..., 'max': ..., 'n': ...} of ``values`` (NaN when empty)."""
    values = np.asarray(values, float)
    out = {f"p{q}": float(np.percentile(values, q)) if values.size else np.nan for q in qs}
    return {**out, "max": float(values.max()) if values.size else np.nan, "n": int(values.size)}


@dataclass
class Envelope:
    """The executor's configured limits, read from the same parameters it was started with."""

    workspace_min: np.ndarray
    workspace_max: np.ndarray
    max_speed: float
    max_force: float
    force_bias: np.ndarray  # the mock's constant F/T bias, base frame (N)
    plane: PlaneFrame
    control_period: float
    sensor_timeout: float
    filter_cutoff_hz: float  # the executor's F/T low-pass

    @property
    def force_grace(self) -> float:
        """Seconds a force above the limit may last before the arm must be still: the F/T
        filter's settling (three time constants) plus two control periods."""
        return 3.0 / (2.0 * np.pi * self.filter_cutoff_hz) + 2.0 * self.control_period

    @classmethod
    def from_config(cls, config: dict) -> Envelope:
        shared = config["/**"]["ros__parameters"]
        executor = config["executor"]["ros__parameters"]
        mock = config["mock_hardware"]["ros__parameters"]
        return cls(
            np.array(executor["workspace_min"], float),
            np.array(executor["workspace_max"], float),
            float(executor["max_speed"]),
            float(executor["max_force"]),
            np.array(mock["force_bias"], float),
            PlaneFrame(shared["plane_origin"], shared["plane_x_axis"], shared["plane_y_axis"]),
            1.0 / float(executor["control_rate_hz"]),
            float(executor["sensor_timeout"]),
            float(executor["filter_cutoff_hz"]),
        )


@dataclass
class Recording:
    """What the probe received. Commands: (stamp s, velocity (3,) m/s, receive monotonic s)."""

    commands: list = field(default_factory=list)
    poses: list = field(default_factory=list)  # (stamp s, position (3,) m)
    wrenches: list = field(default_factory=list)  # (stamp s, force (3,) N)
    reports: list = field(default_factory=list)  # execution.types.Report
    diagnostics: list = field(default_factory=list)  # (receive monotonic s, {key: value}, status)


RECORD_COMMANDS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class Probe(Node):
    """Plays the planner and records the arm side; see the module docstring."""

    def __init__(self, context: Context, record_sensors: bool = True, amplify: int = 1) -> None:
        super().__init__("safety_probe", context=context)
        self.rec = Recording()
        self.episode = 0
        self.nonce = 0  # the episode nonce of the last status (0: none), on every plan
        self.next_id = 1
        self.record_sensors = record_sensors
        self.plan_pub = self.create_publisher(DockingPlan, "/plan", qos.EVENTS)
        self.status_pub = self.create_publisher(EpisodeStatus, "/episode_status", qos.LATCHED)
        # every command, also while this node is busy republishing (the reader's queue fills
        # on the DDS thread; a queue of 1 lost half the commands of the load test)
        self.create_subscription(TwistStamped, COMMAND, self.on_command, RECORD_COMMANDS)
        self.create_subscription(ExecutionReport, "/execution_report", self.on_report, qos.EVENTS)
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, qos.EVENTS)
        if record_sensors:
            self.create_subscription(PoseStamped, POSE, self.on_pose, qos.SENSOR)
            self.create_subscription(WrenchStamped, WRENCH, self.on_wrench, qos.SENSOR)
        self.originals = 0  # sensor samples amplified
        if amplify > 1:  # the load test: each sensor sample arrives `amplify` times
            mock_only = ContentFilterOptions("header.frame_id <> ''", [])  # not our copies
            for msg_type, topic in ((PoseStamped, POSE), (WrenchStamped, WRENCH)):
                publisher = self.create_publisher(msg_type, topic, qos.SENSOR)
                self.create_subscription(
                    msg_type,
                    topic,
                    self.amplifier(publisher, amplify - 1),
                    qos.SENSOR,
                    content_filter_options=mock_only,
                )
        self.drop_clients = {
            s: self.create_client(SetBool, f"/mock_hardware/drop_{s}") for s in STREAM_TOPICS
        }
        self.unanswered: dict[int, DockingPlan] = {}  # plans resent until their report came
        self.create_timer(RESEND_PERIOD, self.resend)
        self.spinner = SingleThreadedExecutor(context=context)
        self.spinner.add_node(self)

    # ---------------------------------------------------------------- callbacks

    def on_command(self, msg: TwistStamped) -> None:
        v = msg.twist.linear
        velocity = np.array([v.x, v.y, v.z])
        self.rec.commands.append((stamp_seconds(msg.header.stamp), velocity, time.monotonic()))

    def on_pose(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        self.rec.poses.append((stamp_seconds(msg.header.stamp), np.array([p.x, p.y, p.z])))

    def on_wrench(self, msg: WrenchStamped) -> None:
        f = msg.wrench.force
        self.rec.wrenches.append((stamp_seconds(msg.header.stamp), np.array([f.x, f.y, f.z])))

    def on_report(self, msg: ExecutionReport) -> None:
        self.rec.reports.append(convert.report_from_msg(msg))
        self.unanswered.pop(msg.plan_id, None)

    def resend(self) -> None:
        """Copies of the unanswered plans, as the planner sends them (the executor's producer
        heartbeat: without them it stops the arm after ``producer_timeout``)."""
        for msg in self.unanswered.values():
            self.plan_pub.publish(msg)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith("executor"):
                values = {kv.key: kv.value for kv in status.values}
                self.rec.diagnostics.append((time.monotonic(), values, status))

    def amplifier(self, publisher, copies: int) -> Callable:
        """Republish each of the mock's samples ``copies`` times, with an empty frame id (which
        the executor reads as its base frame, and by which the probe skips its own copies)."""

        def republish(msg) -> None:
            if msg.header.frame_id:  # without a content filter (rmw): skip our own copies here
                self.originals += 1
                msg.header.frame_id = ""
                for _ in range(copies):
                    publisher.publish(msg)

        return republish

    # ---------------------------------------------------------------- actions

    def spin_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not done() and time.monotonic() < deadline:
            self.spinner.spin_once(timeout_sec=0.02)
        return bool(done())

    def wait_ready(self, timeout_s: float = 60.0) -> bool:
        """Plans matched, commands matched, the services up, the executor's diagnostics
        showing both sensor streams and, when this probe records them, a pose and a wrench
        received here (the executor receiving them says nothing of this node's own
        subscriptions: one that matched only after a move began left no pose before it, and a
        test measuring from there found none)."""

        return self.spin_until(lambda: not self.not_ready(), timeout_s)

    def not_ready(self) -> list[str]:
        """What :meth:`wait_ready` still waits for."""
        checks = {
            "plan subscriber": self.plan_pub.get_subscription_count() > 0,
            "command publisher": self.count_publishers(COMMAND) > 0,
            "drop services": all(c.service_is_ready() for c in self.drop_clients.values()),
            "diagnostics without ERROR": self.sensors_flowing(),
            "pose and wrench recorded": not self.record_sensors
            or bool(self.rec.poses and self.rec.wrenches),
        }
        return [name for name, ok in checks.items() if not ok]

    def diagnostics(self) -> dict[str, str]:
        return self.rec.diagnostics[-1][1] if self.rec.diagnostics else {}

    def sensors_flowing(self, since: float = -np.inf) -> bool:
        """The executor's last diagnostics, received after ``since`` (monotonic), show both
        streams fresher than its sensor timeout."""
        if not self.rec.diagnostics or self.rec.diagnostics[-1][0] <= since:
            return False
        return self.rec.diagnostics[-1][2].level != DiagnosticStatus.ERROR  # WARN: loop late

    def plan(self, waypoints, speed=0.2, threshold=3.0, episode=None, plan_id=None) -> int:
        """Publish a DOCK plan (load straight down, along its last move) with the status's
        nonce; ``plan_id`` None: the next id. Returns its id."""
        if plan_id is None:
            plan_id, self.next_id = self.next_id, self.next_id + 1
        command = PlanCommand(
            plan_id, True, np.array(waypoints, float), np.array([0.0, -1.0]), threshold, speed,
            False, 0.5, 0.5, 0, "safety probe",
            episode=self.episode if episode is None else episode, nonce=self.nonce,
        )  # fmt: skip
        msg = convert.plan_to_msg(
            command, convert.Header(stamp=self.get_clock().now().to_msg(), frame_id="dock_plane")
        )
        self.unanswered[plan_id] = msg
        self.plan_pub.publish(msg)
        return plan_id

    def status(self, episode: int, state: str, nonce: int = 0) -> None:
        """Publish the planner's episode status; the probe's plans carry ``nonce`` after it."""
        header = convert.Header(stamp=self.get_clock().now().to_msg())
        self.status_pub.publish(
            convert.episode_status_to_msg(header, state, episode, "", 0, [], nonce)
        )
        self.episode, self.nonce = episode, nonce

    def wait_episode(self, expected: str, timeout_s: float = 10.0) -> bool:
        """Until the executor's diagnostics report ``expected`` as its episode."""
        return self.spin_until(lambda: self.diagnostics().get("episode") == expected, timeout_s)

    def report(self, plan_id: int, timeout_s: float = 30.0) -> Report | None:
        def found() -> list:
            return [r for r in self.rec.reports if r.plan_id == plan_id]

        return found()[0] if self.spin_until(lambda: bool(found()), timeout_s) else None

    def drop(self, stream: str, stop: bool, timeout_s: float = 10.0) -> bool:
        future = self.drop_clients[stream].call_async(SetBool.Request(data=stop))
        return self.spin_until(future.done, timeout_s) and future.result().success

    def tool(self, envelope: Envelope) -> np.ndarray:
        """The latest tool position in the plane (from the reports when sensors are not
        recorded)."""
        if self.rec.poses:
            return envelope.plane.point_to_plane(self.rec.poses[-1][1])
        if self.rec.reports:
            return self.rec.reports[-1].stop_point
        return np.array(FLOOR["start"], float)


@contextlib.contextmanager
def mock_floor(
    log_dir: Path, overrides: dict | None = None, record_sensors: bool = True, amplify: int = 1
) -> Iterator[tuple[Probe, Envelope, dict]]:
    """executor + mock_hardware on a flat floor (y = 0) as processes, and a ready Probe.

    ``overrides``: {node: {parameter: value}} on top of ``config/mock.yaml``. Yields the probe,
    the envelope of the effective configuration and the processes. ``record_sensors``, ``amplify``:
    see :class:`Probe`."""
    log_dir = Path(log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    config = yaml.safe_load(CONFIG.read_text())
    for node, values in (overrides or {}).items():
        config.setdefault(node, {"ros__parameters": {}})["ros__parameters"].update(values)
    (log_dir / "config.yaml").write_text(yaml.safe_dump(config))
    (log_dir / "floor.yaml").write_text(yaml.safe_dump(FLOOR))
    arguments = {
        "profile": "mock",
        "config": str(log_dir / "config.yaml"),
        "terrain_file": str(log_dir / "floor.yaml"),
    }
    context = Context()
    rclpy.init(context=context)
    probe = Probe(context, record_sensors, amplify)
    try:
        with bringup.running(arguments, log_dir, only={"executor", "mock_hardware"}) as procs:
            probe.respawn = lambda name: bringup.respawn(procs, name, arguments, log_dir)
            if not probe.wait_ready():
                logs = {p.name: p.read_text()[-1500:] for p in log_dir.glob("*.log")}
                missing = probe.not_ready()
                raise RuntimeError(
                    f"executor / mock_hardware: no {missing}; last {probe.diagnostics()}: {logs}"
                )
            yield probe, Envelope.from_config(config), procs
    finally:
        probe.spinner.shutdown()
        probe.destroy_node()
        rclpy.shutdown(context=context)


def traverse(tool: np.ndarray, x: float) -> list:
    """Waypoints: up (or down) to y = 0.3, across to ``x``, down to y = 0.1 (the loading move
    ends 10 cm above the floor: NO_CONTACT, the tool stays in free space for the next plan)."""
    lift = [[tool[0], 0.3]] if abs(tool[1] - 0.3) > 0.01 else []
    return [list(tool), *lift, [x, 0.3], [x, 0.1]]


# --------------------------------------------------------------------------- envelope


def violations(rec: Recording, env: Envelope, still: list[tuple[float, float]] = ()) -> list:
    """Every moving command (speed > 0) that breaks the envelope, as (stamp, reason) pairs.

    Checked per command: finite; speed <= max_speed; the tool (newest pose stamped at or before
    the command) inside the workspace box (1 mm margin: pose noise); not every wrench of the
    last ``force_grace`` seconds above max_force (their force minus the mock's bias, 1 N margin:
    noise; the executor filters the F/T); and no motion inside a ``still`` window (stamps
    (t0, t1) of plans that must be refused)."""
    pose_t = np.array([t for t, _ in rec.poses])
    wrench_t = np.array([t for t, _ in rec.wrenches])
    over = np.array(
        [np.linalg.norm(f - env.force_bias) > env.max_force + 1.0 for _, f in rec.wrenches]
    )
    out = []
    for stamp, velocity, _ in rec.commands:
        speed = float(np.linalg.norm(velocity))
        if speed == 0.0:
            continue
        if not np.all(np.isfinite(velocity)):
            out.append((stamp, "non-finite command"))
            continue
        if speed > env.max_speed * (1 + 1e-9):
            out.append((stamp, f"speed {speed:.3f} m/s above {env.max_speed}"))
        i = int(np.searchsorted(pose_t, stamp, side="right")) - 1
        if i >= 0:
            tool = env.plane.point_to_plane(rec.poses[i][1])
            margin = 1e-3
            if np.any(tool < env.workspace_min - margin) or np.any(
                tool > env.workspace_max + margin
            ):
                out.append((stamp, f"moving with the tool outside the box at {tool.round(3)}"))
        j0, j1 = np.searchsorted(wrench_t, [stamp - env.force_grace, stamp], side="right")
        if j1 > j0 and over[j0:j1].all():
            out.append((stamp, f"moving {env.force_grace:.3f} s into a force above the limit"))
        if any(t0 <= stamp <= t1 for t0, t1 in still):
            out.append((stamp, "moving during a plan that must be refused"))
    return out


def _now(probe: Probe) -> float:
    return probe.get_clock().now().nanoseconds * 1e-9


def _set_episode(probe: Probe, episode: int, state: str) -> None:
    probe.status(episode, state)
    expected = f"{episode} {'RUNNING' if state == 'RUNNING' else 'over'}"
    if not probe.wait_episode(expected):
        raise RuntimeError(f"the executor never reported episode {expected}")


def _nan_then_barrier(probe: Probe, start) -> int:
    """NaN and inf plans are dropped on conversion (no report of their own): the refused plan
    sent after them on the same topic is the barrier that shows they were handled."""
    probe.plan([start, [np.nan, 0.1], [0.0, -0.1]])
    probe.plan([start, [0.0, -0.1]], speed=np.inf)
    return probe.plan([start, [0.0, -0.1]], speed=10.0)


def _superseded(probe: Probe, start) -> int:
    _set_episode(probe, 5, "RUNNING")
    _set_episode(probe, 7, "RUNNING")
    return probe.plan([start, [0.0, -0.1]], episode=5)


def _ended(probe: Probe, start) -> int:
    _set_episode(probe, 9, "RUNNING")
    _set_episode(probe, 9, "ABORTED")
    return probe.plan([start, [0.0, -0.1]])


def force_fault(probe: Probe, env: Envelope, newtons: float = 60.0) -> dict:
    """While a plan moves, the F/T stream is replaced by readings of ``newtons`` along the
    plane's normal (a collision or a sensor fault the mock's physics cannot produce): the
    executor must stop and report ABORTED."""
    tool = probe.tool(env)
    n_commands = len(probe.rec.commands)
    plan_id = probe.plan(traverse(tool, -0.3 if tool[0] > 0 else 0.3), speed=0.1)
    if not probe.spin_until(lambda: _moving(probe.rec.commands[n_commands:]), 15.0):
        return {"outcome": None, "detail": "the arm never moved"}
    assert probe.drop("wrench", True), "drop_wrench failed"
    publisher = probe.create_publisher(WrenchStamped, WRENCH, qos.SENSOR)
    normal = np.cross(env.plane.x_axis, env.plane.y_axis)
    force = newtons * normal + env.force_bias

    def overloaded() -> bool:
        msg = convert.wrench_to_msg(force, convert.Header(frame_id="base_link"))
        msg.header.stamp = probe.get_clock().now().to_msg()
        publisher.publish(msg)
        return any(r.plan_id == plan_id for r in probe.rec.reports)

    probe.spin_until(overloaded, 5.0)
    probe.destroy_publisher(publisher)
    resumed_at = time.monotonic()
    assert probe.drop("wrench", False), "resume wrench failed"
    probe.spin_until(lambda: probe.sensors_flowing(since=resumed_at), 10.0)
    report = probe.report(plan_id, timeout_s=1.0)
    return {
        "outcome": None if report is None else report.outcome_name,
        "detail": None if report is None else report.detail,
    }


def _moving(commands) -> bool:
    return any(np.linalg.norm(v) > 0 for _, v, _ in commands)


def _refusals(env: Envelope) -> dict:
    """name -> (send(probe, start) -> plan id, text the refusal detail must contain)."""
    x_out = env.workspace_max[0] + 0.1
    x_past_floor = 0.5 * (FLOOR_END + env.workspace_max[0])  # nothing below: falls past y_min
    y_below = env.workspace_min[1] - 0.2
    return {
        "target outside the workspace": (
            lambda p, a: p.plan([a, [x_out, 0.3], [x_out, 0.05]]), "workspace"),
        "waypoint below the workspace": (
            lambda p, a: p.plan([a, [x_past_floor, 0.3], [x_past_floor, y_below]]), "workspace"),
        "absurd speed (100 m/s)": (
            lambda p, a: p.plan(traverse(a, 0.3), speed=100.0), "speed"),
        "contact threshold above max_force": (
            lambda p, a: p.plan([a, [0.0, -0.1]], threshold=env.max_force + 10.0), "force"),
        "NaN waypoint, inf speed (dropped)": (_nan_then_barrier, "speed"),
        "plan of a superseded episode": (_superseded, "superseded"),
        "plan of an ended episode": (_ended, "over"),
    }  # fmt: skip


def envelope_scenarios(probe: Probe, env: Envelope, names: list[str] | None = None) -> dict:
    """Plans that must be refused (all, or those ``names``) one after another, a force above
    the limit while a plan moves (:func:`force_fault`), then two plans at once (the first runs,
    the second is refused). Returns per scenario whether it was
    refused as expected and the report's detail, the command counts and every violation
    (:func:`violations`, with the refused plans' spans as windows without motion)."""
    rows, still = [], []
    for name, (send, expect) in _refusals(env).items():
        if names is not None and name not in names:
            continue
        start = probe.tool(env)
        t0 = _now(probe)
        report = probe.report(send(probe, start))
        still.append((t0, _now(probe)))
        ok = report is not None and report.outcome == ExecutionReport.ABORTED
        ok = ok and expect in report.detail and len(report.history) == 0
        detail = "no report" if report is None else report.detail
        rows.append({"scenario": name, "refused": ok, "detail": detail})
    force = {}
    if names is None or "force above the limit" in names:
        _set_episode(probe, 10, "RUNNING")
        force = force_fault(probe, env)
    two = {}
    if names is None or "two plans at once" in names:
        _set_episode(probe, 11, "RUNNING")
        start = probe.tool(env)
        first = probe.plan(traverse(start, 0.2))  # ends above the floor: NO_CONTACT
        second = probe.plan(traverse(start, -0.2))
        report_first, report_second = probe.report(first), probe.report(second)
        two = {
            "first": None if report_first is None else report_first.outcome_name,
            "second": None if report_second is None else report_second.detail,
        }
    bad = violations(probe.rec, env, still)
    moving = sum(float(np.linalg.norm(v)) > 0 for _, v, _ in probe.rec.commands)
    return {
        "refusals": rows,
        "force_fault": force,
        "two_plans": two,
        "commands": len(probe.rec.commands),
        "moving_commands": int(moving),
        "violations": [f"{t:.3f}: {why}" for t, why in bad],
    }


# --------------------------------------------------------------------------- dropout


def dropout(probe: Probe, env: Envelope, stream: str, delay_s: float) -> dict:
    """Start a long move, stop ``stream`` ``delay_s`` after the arm moves, wait for the report.

    Latency = stamp of the first zero command after the stream stopped minus (stamp of the
    stream's last sample + sensor_timeout): the executor's timeout expires ``sensor_timeout``
    after it received the last sample, which is no earlier than that sample's stamp, so the
    figure is conservative (it includes the last sample's delivery delay).
    ``moving_after_stop``: moving commands stamped after that zero command. A run in which
    the arm never moved (its plan aborted first), or whose stream never reached the probe, has
    ``latency_s`` None and an ``error`` (``stop_latency``)."""
    probe.spin_until(probe.sensors_flowing, 30.0)
    samples = probe.rec.wrenches if stream == "wrench" else probe.rec.poses
    # the probe's own subscription too: flowing to the executor is not flowing to the probe (a
    # fresh-clone CI run dropped the wrench before the probe's subscription had matched)
    probe.spin_until(lambda: len(samples) > 0, 10.0)
    tool = probe.tool(env)
    n_commands = len(probe.rec.commands)
    plan_id = probe.plan(traverse(tool, -0.5 if tool[0] > 0 else 0.5), speed=0.1)
    if not probe.spin_until(lambda: _moving(probe.rec.commands[n_commands:]), 15.0):
        report = probe.report(plan_id, timeout_s=1.0)
        detail = None if report is None else report.detail
        return {"stream": stream, "latency_s": None, "moving_after_stop": 0, "outcome": None,
                "detail": detail, "segments": None, "error": "the arm never moved"}  # fmt: skip
    probe.spin_until(lambda: False, delay_s)
    assert probe.drop(stream, True), f"drop_{stream} failed"
    report = probe.report(plan_id, timeout_s=10.0)
    # the zero command goes out just before the report, on another topic: the probe may take
    # the report first (latency None then, though the arm was stopped)
    probe.spin_until(
        lambda: (
            stop_latency(samples, probe.rec.commands[n_commands:], 0.0)["latency_s"] is not None
        ),
        1.0,
    )
    stop = stop_latency(samples, probe.rec.commands[n_commands:], env.sensor_timeout)

    def error() -> str:
        last = probe.rec.diagnostics[-1][2] if probe.rec.diagnostics else None
        return last.message if last and last.level == DiagnosticStatus.ERROR else ""

    probe.spin_until(error, 5.0)  # /diagnostics names the stale stream
    diagnostics = error()
    resumed_at = time.monotonic()
    assert probe.drop(stream, False), f"resume {stream} failed"
    probe.spin_until(lambda: probe.sensors_flowing(since=resumed_at), 10.0)
    return {
        "stream": stream,
        **stop,
        "outcome": None if report is None else report.outcome_name,
        "detail": None if report is None else report.detail,
        "segments": None if report is None else len(report.history),
        "diagnostics_error": diagnostics,
    }


def stop_latency(samples, commands, sensor_timeout: float) -> dict:
    """``latency_s``: stamp of the first zero command after the stream's last sample (stamp s,
    value) minus (that stamp + ``sensor_timeout``); ``moving_after_stop``: moving commands
    (stamp, velocity, receive time) stamped after that zero. ``latency_s`` is None when no zero
    command came after the last sample, and also, with an ``error`` saying why, when the probe
    got no sample of the stream (best effort: a loaded machine may deliver none to it)."""
    if not samples:
        return {"latency_s": None, "moving_after_stop": 0,
                "error": "the probe received no sample of the stream"}  # fmt: skip
    last = max(t for t, _ in samples)
    after = [(t, v) for t, v, _ in commands if t > last]
    zero = [t for t, v in after if np.linalg.norm(v) == 0.0]
    late = [t for t, v in after if np.linalg.norm(v) > 0 and zero and t > zero[0]]
    return {"latency_s": (zero[0] - last - sensor_timeout) if zero else None,
            "moving_after_stop": len(late)}  # fmt: skip


# --------------------------------------------------------------------------- executor exit


def _at(poses, stamp: float) -> np.ndarray | None:
    """The newest recorded position (3,) stamped at or before ``stamp``."""
    before = [p for t, p in poses if t <= stamp]
    return before[-1] if before else None


def _at_rest(poses, since: float, window_s: float = 0.1, tolerance_m: float = 5e-4) -> bool:
    """The poses stamped in the last ``window_s`` (all after ``since``) stay within
    ``tolerance_m`` of the newest one (the mock's pose noise is 0.1 mm per axis)."""
    if not poses or poses[-1][0] < since + window_s:
        return False
    newest = poses[-1][1]
    recent = [p for t, p in poses if t >= poses[-1][0] - window_s]
    return all(np.linalg.norm(p - newest) <= tolerance_m for p in recent)


def executor_exit(
    probe: Probe,
    env: Envelope,
    processes: dict,
    signum: int,
    delay_s: float = 0.3,
    respawn: bool = True,
) -> dict:
    """Start a long move at 0.2 m/s, send ``signum`` to the executor process ``delay_s`` after
    the arm moves, wait for the process to end and the tool to come to rest, then (``respawn``)
    start the executor again (``Probe.respawn``) and wait until it is ready.

    Returns ``distance_m``: how far the tool moved from its position at the signal until at
    rest (base frame; the mock's own ``command_timeout`` bounds it when no stop comes; None
    when no pose came before the signal or the tool was not seen at rest within 10 s:
    ``at_rest`` and ``poses_after_signal``, the poses received after it, tell which);
    ``zero_command``: a zero command stamped after the signal arrived; ``moving_after_zero``:
    moving commands stamped after that one; the exit code; ``error`` when the arm never moved."""
    name = signal.Signals(signum).name
    tool = probe.tool(env)
    n_commands = len(probe.rec.commands)
    plan_id = probe.plan(traverse(tool, -0.5 if tool[0] > 0 else 0.5), speed=0.2)
    if not probe.spin_until(lambda: _moving(probe.rec.commands[n_commands:]), 15.0):
        probe.unanswered.pop(plan_id, None)
        return {"signal": name, "distance_m": None, "error": "the arm never moved"}
    probe.spin_until(lambda: False, delay_s)
    process = processes["executor"]
    t_signal = _now(probe)
    process.send_signal(signum)
    probe.unanswered.pop(plan_id, None)  # the planner's part: no copies for a new executor
    probe.spin_until(lambda: process.poll() is not None, 15.0)
    exit_code = process.poll()
    rest = probe.spin_until(lambda: _at_rest(probe.rec.poses, t_signal), 10.0)
    start, end = _at(probe.rec.poses, t_signal), probe.rec.poses[-1][1]
    after = [
        float(np.linalg.norm(v)) for t, v, _ in probe.rec.commands[n_commands:] if t > t_signal
    ]
    zero = after.index(0.0) if 0.0 in after else None
    respawned_at = time.monotonic()
    if exit_code is None:
        process.kill()
        process.wait()
    ready = None
    if respawn:
        probe.respawn("executor")
        ready = probe.spin_until(
            lambda: probe.sensors_flowing(since=respawned_at) and not probe.not_ready(), 60.0
        )
    return {
        "signal": name,
        "exit_code": exit_code,
        "distance_m": None if start is None or not rest else float(np.linalg.norm(end - start)),
        "zero_command": zero is not None,
        "moving_after_zero": 0 if zero is None else sum(v > 0.0 for v in after[zero:]),
        "respawned": ready,
        "at_rest": bool(rest),
        "poses_after_signal": sum(t > t_signal for t, _ in probe.rec.poses),
    }


# --------------------------------------------------------------------------- load


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc), seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _tick_counts(diagnostics: list[dict]) -> dict:
    """Control ticks, late ticks and the longest tick interval (s) the executor reported
    between the first and the last of ``diagnostics`` (its /diagnostics values)."""
    if len(diagnostics) < 2:
        return {"ticks": 0, "late": 0, "max_interval_s": None}
    first, last = diagnostics[0], diagnostics[-1]
    return {
        "ticks": int(last["control_ticks"]) - int(first["control_ticks"]),
        "late": int(last["control_late_ticks"]) - int(first["control_late_ticks"]),
        "max_interval_s": max(float(d["control_max_period_s"]) for d in diagnostics[1:]),
    }


def control_jitter(
    probe: Probe,
    env: Envelope,
    burst_size: int = 0,
    burst_period_s: float = 0.25,
    executor_pid: int | None = None,
) -> dict:
    """Run one plan (0.7 m at 0.2 m/s); every ``burst_period_s`` of its first 2 s publish
    ``burst_size`` more plans (refused: one runs; harmless free-space moves if one slipped
    through). Intervals between the stamps of consecutive commands of the run, and their
    jitter |interval - control period| (p50/p99/max, seconds); the same from the probe's
    receive times; the executor's own count of control ticks during the run, of late ones
    (more than 2 periods after the previous) and its longest tick interval (its diagnostics);
    the refusals' details; the executor's diagnostics at the end and, given its pid, its CPU
    use during the run (% of one core)."""
    tool = probe.tool(env)
    x = -0.5 if tool[0] > 0 else 0.5
    n_commands, n_reports = len(probe.rec.commands), len(probe.rec.reports)
    n_diagnostics, originals = len(probe.rec.diagnostics), probe.originals
    cpu0 = cpu_seconds(executor_pid) if executor_pid else 0.0
    plan_id = probe.plan(traverse(tool, x), speed=0.2)
    burst_ids = []
    t0 = time.monotonic()
    while burst_size and time.monotonic() < t0 + 2.0 and not probe.report(plan_id, 0.0):
        burst_ids += [probe.plan([[x, 0.3], [x, 0.2]]) for _ in range(burst_size)]
        probe.spin_until(lambda: False, burst_period_s)
    report = probe.report(plan_id, timeout_s=30.0)
    at_end, elapsed = len(probe.rec.commands), time.monotonic() - t0
    cpu = (cpu_seconds(executor_pid) - cpu0) / elapsed * 100 if executor_pid else None
    during = [v for _, v, _ in probe.rec.diagnostics[n_diagnostics:]]
    probe.spin_until(lambda: False, 0.5)  # reports of the last burst (best effort)
    stamps = np.array([t for t, _, _ in probe.rec.commands[n_commands:at_end]])
    received = np.array([r for _, _, r in probe.rec.commands[n_commands:at_end]])
    intervals = np.diff(stamps)
    bursts = [r for r in probe.rec.reports[n_reports:] if r.plan_id in set(burst_ids)]
    return {
        "outcome": None if report is None else report.outcome_name,
        "detail": None if report is None else report.detail,
        "commands": int(stamps.size),
        "burst_plans": len(burst_ids),
        "burst_reports": len(bursts),
        "burst_details": sorted({r.detail for r in bursts}),
        "interval_s": percentiles(intervals),
        "jitter_s": percentiles(np.abs(intervals - env.control_period)),
        "receive_jitter_s": percentiles(np.abs(np.diff(received) - env.control_period)),
        "mock_rate_hz": (probe.originals - originals) / 2 / elapsed,  # per stream; 0 unamplified
        "executor_rate_hz": {  # the median over the run of what the executor received
            k: float(np.median([float(d[f"{k}_rate_hz"]) for d in during])) if during else 0.0
            for k in ("wrench", "tool_pose")
        },
        "executor_cpu_percent": cpu,
        "executor_ticks": _tick_counts(during),
        "diagnostics": probe.diagnostics(),
    }
