"""Fuzzing every subscription of every node with malformed messages.

Two seeded, bounded runs over the same mutations (``tools.fuzz_messages``):

* :func:`in_process`: each node of the mock launch file is built in-process and every one of
  its subscriptions (``node.subscriptions``, so a new one is never missed) gets ``messages``
  mutations through its guarded callback. Exact figures: exceptions escaping a callback, and
  malformed messages a node did not drop (``node.malformed`` counts the drops): the silent uses.
* :func:`over_dds`: the five nodes as processes (``tools.bringup``, mock profile, depth prior).
  The subscriptions are read from the ROS graph per node; a type without a mutation table is an
  error. A fuzzer node seeds a contact history (episodes 1, 2; valid reports of plans 1, 2),
  publishes ``messages`` mutations per topic, interleaved, then a valid probe report (plan 3),
  which must extend the latched ``/contact_history`` by its segment alone, and then runs a
  normal episode (``tools.episode``), which must still dock. Figures: node deaths (a process
  that exited), tracebacks in the node logs, corrupted contact history, malformed-input log
  lines (throttled per cause) and the drops each node counted.

    python -m tactile_dock_ros.tools.bench fuzz --messages 1000 --seed 0 --json out.json
"""

from __future__ import annotations

import importlib
import re
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header, UInt32

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.execution.types import PlaneFrame
from tactile_dock_ros.msg import ContactHistory, EpisodeStatus, ShapeDistribution
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.nodes.common import MAX_HOLDS, node_class
from tactile_dock_ros.tools import bringup, fuzz_messages
from tactile_dock_ros.tools.fuzz_messages import FuzzContext

ARGUMENTS = {"profile": "mock", "problem": "sloper", "seed": "0", "prior_source": "depth"}
PLANE_FRAME, BASE_FRAME = "dock_plane", "base_link"  # config/mock.yaml
# Topics whose messages on the running suite are the bases of their mutations (over DDS).
LIVE_TOPICS = (
    "/terrain_prior", "/episode_status", "/arm/tool_pose", "/ft_sensor/wrench",
    "/camera/depth/image_raw", "/camera/depth/camera_info",
)  # fmt: skip
# Topics whose subscribers check the frame_id (a wrong one is malformed there).
FRAME_CHECKED = {
    "/terrain_prior",
    "/contact_history",
    "/shape_samples",
    "/plan",
    "/execution_report",
    "/arm/tool_pose",
    "/ft_sensor/wrench",
    "/arm/cmd_twist",
    "/camera/depth/image_raw",
    "/camera/depth/camera_info",
}
# The seeded state: episode 2 after episode 1, reports of plans 1 and 3 (plan 2 is then out of
# order); the probe is plan 4. The planner's episode ids are clock milliseconds, never 1 or 2.
EPISODES, SEED_PLANS, PROBE_PLAN = (1, 2), (1, 3), 4


def _type_name(msg_type) -> str:
    module = msg_type.__module__.split(".")
    return f"{module[0]}/{module[1]}/{msg_type.__name__}"


def _header(sec: int, frame_id: str) -> Header:
    return Header(stamp=Time(sec=sec), frame_id=frame_id)


def bases(now_s: int, live: dict) -> dict:
    """Topic -> the valid message its mutations start from; ``live`` (topic -> message seen on
    the running suite) overrides the constructed ones (then a well-formed mutation carries
    the suite's own content, e.g. the prior)."""
    plane, base = _header(now_s, PLANE_FRAME), _header(now_s, BASE_FRAME)
    prior = problems.get(ARGUMENTS["problem"]).prior
    seeded = _seed_state()
    frame = PlaneFrame([0.0, 0.6, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    camera = _header(now_s, "depth_camera")
    K = np.array([[30.0, 0.0, 15.5], [0.0, 30.0, 11.5], [0.0, 0.0, 1.0]])
    out = {
        "/terrain_prior": convert.shape_to_msg(prior, plane),
        "/contact_history": convert.history_to_msg(seeded, plane),
        "/shape_samples": convert.samples_to_msg(
            np.repeat(prior.mean_vertices[None], 4, axis=0),
            plane,
            "hmc",
            4.0,
            len(seeded.history),
        ),
        "/plan": fuzz_messages.valid_plan(EPISODES[-1], PROBE_PLAN + 1, plane),
        "/execution_report": fuzz_messages.valid_report(EPISODES[-1], SEED_PLANS[0], -0.3, plane),
        "/episode": UInt32(data=EPISODES[-1]),
        "/episode_status": convert.episode_status_to_msg(_header(now_s, ""), "IDLE", 0, "", 0, []),
        "/sample_request": convert.sample_request_to_msg(
            _header(now_s, ""), EPISODES[-1], 0, 0, len(seeded.history), 400
        ),
        "/arm/tool_pose": convert.pose_to_msg(frame.point_from_plane([0.0, 0.45]), base),
        "/ft_sensor/wrench": convert.wrench_to_msg(np.array([0.3, -0.2, 0.5]), base),
        "/arm/cmd_twist": convert.twist_to_msg(np.zeros(3), base),
        "/camera/depth/image_raw": convert.depth_to_image(np.full((24, 32), 1.0), camera),
        "/camera/depth/camera_info": convert.camera_info(K, 32, 24, camera),
    }
    return {**out, **live}


def _seed_reports(header: Header) -> list:
    return [fuzz_messages.valid_report(EPISODES[-1], p, -0.3 + 0.1 * p, header) for p in SEED_PLANS]


def _seed_state() -> EpisodeState:
    """The episode as inference holds it once it has the seed reports."""
    state = EpisodeState()
    for report in map(convert.report_from_msg, _seed_reports(Header())):
        state = state.record(report.history, report.plan_id)
    return state


def seed_messages(now_s: int) -> list[tuple[str, object]]:
    """(topic, message) in order: the state the fuzzing starts from (an episode 2 after an
    episode 1, with the reports of plans 1 and 3 in the contact history)."""
    reports = _seed_reports(_header(now_s, PLANE_FRAME))
    return [("/episode", UInt32(data=e)) for e in EPISODES] + [
        ("/execution_report", r) for r in reports
    ]


def _context(now_s: int) -> FuzzContext:
    return FuzzContext(now_s=now_s, episodes=EPISODES, reported_plans=SEED_PLANS)


# --------------------------------------------------------------------------- in-process


def in_process(messages: int, seed: int, params_dir: Path) -> dict:
    """Every subscription of every node, called directly with ``messages`` mutations each."""
    rows = {}
    for spec in bringup.nodes(ARGUMENTS):
        argv = spec.command(bringup.PACKAGE_ROOT / "scripts", params_dir)
        context = Context()
        rclpy.init(context=context)
        node = node_class(spec.executable)(
            context=context, cli_args=argv[argv.index("--ros-args") :]
        )
        try:
            rows[spec.name] = _fuzz_node(node, messages, seed)
        finally:
            node.destroy_node()
            rclpy.shutdown(context=context)
    return rows


def _deliver(subscription, msg) -> None:
    """Call ``subscription``'s callback with ``msg`` as rclpy would: serialized for the raw
    subscriptions of ``common.subscribe`` (their guard checks the size, then deserializes)."""
    subscription.callback(serialize_message(msg) if subscription.raw else msg)


def _fuzz_node(node: Node, messages: int, seed: int) -> dict:
    now_s = int(node.get_clock().now().nanoseconds // 10**9)
    subscriptions = {s.topic_name: s for s in node.subscriptions}
    base = bases(now_s, {})
    live = {
        "/terrain_prior": base["/terrain_prior"],
        "/episode_status": base["/episode_status"],
        "/camera/depth/camera_info": base["/camera/depth/camera_info"],
    }
    for topic, msg in [*live.items(), *seed_messages(now_s)]:
        if topic in subscriptions:
            _deliver(subscriptions[topic], msg)
    state = getattr(node, "episode_state", None)  # inference's and the planner's history
    out = {}
    for index, (topic, subscription) in enumerate(sorted(subscriptions.items())):
        rng = np.random.default_rng([seed, index])
        stats = Counter()
        errors = Counter()
        for m in fuzz_messages.mutations(
            _type_name(subscription.msg_type),
            base[topic],
            messages,
            rng,
            _context(now_s),
            topic in FRAME_CHECKED,
        ):
            before = node.malformed.dropped[topic], _refused(node)
            try:
                _deliver(subscription, m.msg)
            except Exception as err:  # counted: the figure is that none escapes
                errors[f"{m.kind}: {type(err).__name__}: {err}"[:200]] += 1
                continue
            dropped = (node.malformed.dropped[topic], _refused(node)) != before
            stats["malformed" if m.malformed else "well_formed"] += 1
            stats["dropped"] += dropped
            if m.malformed and not dropped:
                stats[f"accepted malformed: {m.kind}"] += 1
        out[topic] = {"messages": messages, **stats, "exceptions": dict(errors)}
    if state is not None:
        out["history_unchanged"] = _same_history(state.history, node.episode_state.history)
    return out


def _refused(node) -> int:
    """Plans the executor refused with an ABORTED report (a plan of an episode that is not
    running, say): not used, like a dropped message, but answered."""
    health = getattr(node, "health", None)
    return health.counts["plans_refused"] if health is not None else 0


def _same_history(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x, y) for x, y in ((a.a, b.a), (a.b, b.b), (a.status, b.status))
    )


# --------------------------------------------------------------------------- over DDS


class Fuzzer(Node):
    """Keeps the newest message of the suite's topics (bases, history) and publishes."""

    def __init__(self, **kwargs) -> None:
        super().__init__("fuzzer", **kwargs)
        self.live: dict[str, object] = {}
        self.histories = 0  # /contact_history messages received
        watched = [
            (ContactHistory, "/contact_history", qos.LATCHED),
            (EpisodeStatus, "/episode_status", qos.LATCHED),
            (ShapeDistribution, "/terrain_prior", qos.priors(MAX_HOLDS.default)),
            (PoseStamped, "/arm/tool_pose", qos.SENSOR),
            (WrenchStamped, "/ft_sensor/wrench", qos.SENSOR),
            (Image, "/camera/depth/image_raw", qos.SENSOR),
            (CameraInfo, "/camera/depth/camera_info", qos.SENSOR),
        ]
        for msg_type, topic, profile in watched:
            self.create_subscription(msg_type, topic, lambda m, t=topic: self._keep(t, m), profile)

    def _keep(self, topic: str, msg) -> None:
        self.live[topic] = msg
        self.histories += topic == "/contact_history"

    def history_rows(self) -> list[tuple]:
        msg = self.live.get("/contact_history")
        segments = [] if msg is None else msg.segments
        return [(s.start.x, s.start.y, s.end.x, s.end.y, s.status, s.plan_id) for s in segments]

    def subscriptions_of(self, names) -> dict[str, dict]:
        """Topic -> {type, subscribers} from the ROS graph, for the nodes ``names``."""
        topics: dict[str, dict] = {}
        for name in names:
            try:
                found = self.get_subscriber_names_and_types_by_node(name, "/")
            except NodeNameNonExistentError:  # not discovered yet
                continue
            for topic, types in found:
                entry = topics.setdefault(topic, {"type": types[0], "subscribers": []})
                entry["subscribers"].append(name)
        return topics

    def publisher_for(self, topic: str, msg_type):
        """Reliable (matches best-effort readers), transient local if a reader is."""
        infos = self.get_subscriptions_info_by_topic(topic)
        latched = any(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        profile = QoSProfile(
            depth=10,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        return self.create_publisher(msg_type, topic, profile)


def _spin_until(executor, done, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return bool(done())


def _msg_type(type_name: str):
    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def over_dds(
    messages: int,
    seed: int,
    log_dir: Path,
    episode_timeout_s: float = 0.0,
    expected: set[tuple[str, str]] = frozenset(),
    progress=print,
) -> dict:
    """Fuzz the running suite; ``episode_timeout_s`` > 0 then runs a normal episode.
    ``expected``: (node, topic) subscriptions (from :func:`in_process`) the graph must show
    before the fuzzing starts (discovery is gradual); every one the graph shows is fuzzed."""
    log_dir = Path(log_dir)
    context = Context()
    rclpy.init(context=context)
    fuzzer = Fuzzer(context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(fuzzer)
    result: dict = {"messages_per_topic": messages, "seed": seed}
    try:
        with bringup.running(ARGUMENTS, log_dir) as processes:
            names = list(processes)
            needed = set(LIVE_TOPICS)  # no history yet: inference publishes one per episode id
            if not _spin_until(executor, lambda: needed <= set(fuzzer.live), 120.0):
                raise TimeoutError(
                    f"the suite did not come up: {needed - set(fuzzer.live)} missing"
                )

            def discovered():
                pairs = _pairs(fuzzer.subscriptions_of(names))
                return set(names) <= {n for n, _ in pairs} and expected <= pairs

            if not _spin_until(executor, discovered, 60.0):
                missing = expected - _pairs(fuzzer.subscriptions_of(names))
                raise TimeoutError(f"subscriptions not in the ROS graph: {sorted(missing)}")
            topics = fuzzer.subscriptions_of(names)
            for entry in topics.values():
                fuzz_messages.table(entry["type"], False)  # KeyError: a type nobody can fuzz
            progress(
                f"{len(topics)} topics, {sum(len(t['subscribers']) for t in topics.values())}"
                " subscriptions: " + ", ".join(sorted(topics))
            )
            now_s = int(fuzzer.get_clock().now().nanoseconds // 10**9)
            publishers = {
                t: fuzzer.publisher_for(t, _msg_type(e["type"])) for t, e in topics.items()
            }
            _spin_until(
                executor, lambda: all(p.get_subscription_count() for p in publishers.values()), 30.0
            )
            seeded = _seed(fuzzer, executor, publishers, now_s)
            baseline = fuzzer.history_rows()
            result["history_seeded"] = seeded and len(baseline) == len(SEED_PLANS)
            base = bases(now_s, {t: fuzzer.live[t] for t in LIVE_TOPICS})
            t0 = time.monotonic()
            result["topics"] = _publish(
                fuzzer, executor, publishers, topics, base, messages, seed, now_s, processes
            )
            result["fuzz_seconds"] = time.monotonic() - t0
            for topic, publisher in publishers.items():
                if topic != "/execution_report":
                    fuzzer.destroy_publisher(publisher)
            result["history"] = _probe(fuzzer, executor, publishers["/execution_report"], now_s,
                                       baseline)  # fmt: skip
            if episode_timeout_s > 0:
                result["episode"] = _normal_episode(context, executor, episode_timeout_s, progress)
            result["exit_codes"] = {n: p.poll() for n, p in processes.items()}
    finally:
        executor.shutdown()
        fuzzer.destroy_node()
        rclpy.shutdown(context=context)
    result["nodes"] = {
        n: _log_figures(log_dir / f"{n}.log", code)
        for n, code in result.get("exit_codes", {}).items()
    }
    result["deaths"] = sum(v["died"] for v in result["nodes"].values())
    result["tracebacks"] = sum(v["tracebacks"] for v in result["nodes"].values())
    return result


def _probe(fuzzer, executor, publisher, now_s: int, baseline: list) -> dict:
    """A valid report of the next plan must extend the history by its segment alone."""
    probe = fuzz_messages.valid_report(EPISODES[-1], PROBE_PLAN, 0.0, _header(now_s, PLANE_FRAME))
    probe_row = (0.0, 0.5, 0.0, 0.4, 0, PROBE_PLAN)
    publisher.publish(probe)
    answered = _spin_until(executor, lambda: fuzzer.history_rows() == [*baseline, probe_row], 120.0)
    rows = fuzzer.history_rows()
    fuzzer.destroy_publisher(publisher)
    return {
        "seeded_segments": len(baseline),
        "after_probe_segments": len(rows),
        "probe_answered": answered,
        "corrupted": rows[: len(baseline)] != baseline
        or any(r != probe_row for r in rows[len(baseline) :]),
    }


def _pairs(topics: dict) -> set[tuple[str, str]]:
    """(node, topic) of every subscription in ``subscriptions_of``'s answer."""
    return {(name, topic) for topic, entry in topics.items() for name in entry["subscribers"]}


def _seed(fuzzer, executor, publishers, now_s: int) -> bool:
    ok = True
    for topic, msg in seed_messages(now_s):
        count = fuzzer.histories
        publishers[topic].publish(msg)
        ok &= _spin_until(executor, lambda c=count: fuzzer.histories > c, 30.0)
    return ok


def _publish(fuzzer, executor, publishers, topics, base, messages, seed, now_s, processes):
    streams, stats = {}, {}
    for index, (topic, entry) in enumerate(sorted(topics.items())):
        rng = np.random.default_rng([seed, index])
        streams[topic] = fuzz_messages.mutations(
            entry["type"], base[topic], messages, rng, _context(now_s), topic in FRAME_CHECKED
        )
        stats[topic] = {**entry, "sent": 0, "malformed": 0, "kinds": Counter()}
    for _ in range(messages):
        for topic, stream in streams.items():
            m = next(stream)
            publishers[topic].publish(m.msg)
            stats[topic]["sent"] += 1
            stats[topic]["malformed"] += m.malformed
            stats[topic]["kinds"][m.kind] += 1
        executor.spin_once(timeout_sec=0.0)
        if not fuzzer.context.ok():  # rclpy's SIGINT handler shut it down
            raise KeyboardInterrupt
        if any(p.poll() is not None for p in processes.values()):
            break  # a node died: the figures say which
    return stats


def _normal_episode(context, executor, timeout_s: float, progress) -> dict:
    from tactile_dock_ros.tools import episode

    client = episode.EpisodeClient(context=context)
    executor.add_node(client)
    try:
        record = client.run(executor, timeout_s, progress=progress)
    finally:
        executor.remove_node(client)
        client.destroy_node()
    return {"state": record.state, "cycles": len(record.plans), "wall_s": record.wall_seconds}


_DROPPED = re.compile(r"malformed messages dropped: (.*)$")


def _log_figures(path: Path, exit_code) -> dict:
    """From a node's log: tracebacks, malformed-input log lines, the drop counts it logged at
    shutdown; died: it exited before it was stopped."""
    text = path.read_text(errors="replace") if path.exists() else ""
    dropped = {}
    for line in text.splitlines():
        match = _DROPPED.search(line)
        if match:
            for item in match.group(1).split(", "):
                topic, _, count = item.rpartition(" ")
                dropped[topic] = int(count)
    return {
        "died": exit_code is not None,
        "exit_code": exit_code,
        "tracebacks": text.count("Traceback (most recent call last)"),
        "drop_log_lines": sum(
            " message: " in line and "dropped " in line for line in text.splitlines()
        ),
        "dropped": dropped,
    }


# --------------------------------------------------------------------------- bench suite


def add_arguments(parser) -> None:
    parser.add_argument("--messages", type=int, default=1000, help="mutations per topic")
    parser.add_argument(
        "--episode-timeout",
        type=float,
        default=300.0,
        help="seconds for the normal episode after fuzzing (0: skip it)",
    )
    parser.add_argument("--log-dir", type=Path, help="node logs (default: a temporary directory)")


def run(args) -> dict:
    bringup.isolate_dds()
    log_dir = args.log_dir or Path(tempfile.mkdtemp(prefix="bench_fuzz_"))
    with tempfile.TemporaryDirectory() as params_dir:
        local = in_process(args.messages, args.seed, Path(params_dir))
    expected = {(n, t) for n, rows in local.items() for t, r in rows.items() if isinstance(r, dict)}
    dds = over_dds(args.messages, args.seed, log_dir, args.episode_timeout, expected)
    summary = summarize(local, dds)
    for key, value in summary.items():
        print(f"{key:<42} {value}")
    return {"summary": summary, "in_process": local, "dds": dds, "log_dir": str(log_dir)}


def summarize(local: dict, dds: dict) -> dict:
    """The figures of the README table."""
    per_topic = [row for node in local.values() for row in node.values() if isinstance(row, dict)]
    episode = dds.get("episode") or {}
    return {
        "topics (DDS)": len(dds["topics"]),
        "subscriptions (in-process)": len(per_topic),
        "messages per topic": dds["messages_per_topic"],
        "messages sent (DDS)": sum(t["sent"] for t in dds["topics"].values()),
        "malformed sent (DDS)": sum(t["malformed"] for t in dds["topics"].values()),
        "node deaths": dds["deaths"],
        "tracebacks in node logs": dds["tracebacks"],
        "exceptions escaping a callback (in-process)": sum(
            sum(r["exceptions"].values()) for r in per_topic
        ),
        "malformed accepted (in-process)": sum(
            v for r in per_topic for k, v in r.items() if k.startswith("accepted malformed")
        ),
        "contact history corrupted (DDS)": dds["history"]["corrupted"],
        "contact history corrupted (in-process)": not local["inference"]["history_unchanged"],
        "malformed-input log lines (DDS)": sum(n["drop_log_lines"] for n in dds["nodes"].values()),
        "drops counted by the nodes (DDS)": sum(
            sum(n["dropped"].values()) for n in dds["nodes"].values()
        ),
        "episode after fuzzing": episode.get("state", "not run"),
        "episode cycles": episode.get("cycles"),
    }
