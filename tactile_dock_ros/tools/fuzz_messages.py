"""Seeded mutations of valid messages, one table per message type (used by tools.fuzz).

Each :class:`Mutation` says whether it is *malformed* (NaN / inf fields, empty or mismatched
arrays, arrays of 10^6 elements or past the contract's limits, a wrong frame_id, a stamp far in
the future or not a time, an unknown encoding or enum value, a zero-size image): every
subscriber must drop it. The others are well formed but stale or repeated (a stamp far in the
past, a duplicated or out-of-order episode / plan id, a plan or report of another episode):
the nodes must ignore them by design, so they change no state that matters.

Arrays of nested messages (Point[], ContactSegment[]) are made one element past their limit
(``nodes.validate``) rather than 10^6 long: rclpy builds a Python object per element before any
callback runs, so their size is bounded by the limit check, not by allocation.
"""

from __future__ import annotations

import array
import copy
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3

from tactile_dock_ros.msg import ContactSegment, DockingPlan, ExecutionReport
from tactile_dock_ros.nodes import validate

HUGE = 1_000_000  # elements of a huge primitive array
NAN, INF = float("nan"), float("inf")


@dataclass(frozen=True)
class Mutation:
    kind: str
    malformed: bool
    msg: object


@dataclass
class FuzzContext:
    """What the mutations refer to: the node clock (s), the episode ids the nodes have seen
    (oldest first, the last one current) and the plan ids already reported in it (with a gap
    below the last: that id is out of order)."""

    now_s: int
    episodes: tuple[int, ...]
    reported_plans: tuple[int, ...]
    cache: dict = field(default_factory=dict)  # huge messages, built once


def _floats(n: int) -> array.array:
    return array.array("d", bytes(8 * n))


def _poison(values, value: float, rng) -> array.array:
    out = array.array("d", values)
    if len(out):
        out[int(rng.integers(len(out)))] = value
    return out


def _cached(ctx: FuzzContext, key: str, build: Callable[[], object]):
    if key not in ctx.cache:
        ctx.cache[key] = build()
    return ctx.cache[key]


def _points(n: int) -> list[Point]:
    return [Point(x=0.001 * i, y=0.0, z=0.0) for i in range(n)]


def _segments(n: int) -> list[ContactSegment]:
    return [
        ContactSegment(start=Point(x=0.001 * i), end=Point(x=0.001 * i + 5e-4)) for i in range(n)
    ]


# Each table row: (kind, malformed, fn(msg, rng, ctx) -> replacement message or None).
Row = tuple[str, bool, Callable]


def _set(attribute: str, value) -> Callable:
    def fn(msg, rng, ctx):
        target = msg
        *path, last = attribute.split(".")
        for name in path:
            target = getattr(target, name)
        setattr(target, last, value(rng, ctx) if callable(value) else value)

    return fn


def _set_many(**values) -> Callable:
    def fn(msg, rng, ctx):
        for name, value in values.items():
            setattr(msg, name, value)

    return fn


def _stamp_rows(frame_checked: bool) -> list[Row]:
    def stamp(sec, nanosec=0):
        return _set("header.stamp", lambda rng, ctx: Time(sec=sec(ctx), nanosec=nanosec))

    return [
        ("stamp far future", True, stamp(lambda ctx: ctx.now_s + 10**6)),
        ("stamp nanosec >= 1e9", True, stamp(lambda ctx: ctx.now_s, 1_500_000_000)),
        ("stamp negative", True, stamp(lambda ctx: -5)),
        ("stamp far past", False, stamp(lambda ctx: 1)),
        ("wrong frame_id", frame_checked, _set("header.frame_id", "not_a_frame")),
    ]


def _vector_rows(prefix: str, fields: tuple[str, ...]) -> list[Row]:
    rows = []
    for name in fields:
        rows.append((f"{name} NaN", True, _set(f"{prefix}.{name}.x", NAN)))
        rows.append((f"{name} inf", True, _set(f"{prefix}.{name}.y", -INF)))
    return rows


def _shape_rows() -> list[Row]:
    return [
        ("mean NaN", True, lambda m, rng, ctx: setattr(m, "mean", _poison(m.mean, NAN, rng))),
        ("basis inf", True, lambda m, rng, ctx: setattr(m, "basis", _poison(m.basis, INF, rng))),
        ("num_vertices 0", True, _set("num_vertices", 0)),
        ("num_vertices 1", True, _set("num_vertices", 1)),
        ("num_vertices over limit", True, _set("num_vertices", validate.MAX_VERTICES + 1)),
        ("num_basis over limit", True, _set("num_basis", 2**32 - 1)),
        ("mean mismatched length", True, lambda m, rng, ctx: setattr(m, "mean", m.mean[:-1])),
        ("basis empty", True, _set("basis", _floats(0))),
        ("mean 10^6", True, lambda m, rng, ctx: setattr(m, "mean", _floats(HUGE))),
        ("friction NaN", True, _set("friction", NAN)),
        ("friction negative", True, _set("friction", -0.5)),
    ]


_zero_length = _set_many(status=ContactSegment.STICK, start=Point(), end=Point())


def _history_rows() -> list[Row]:
    def segment(change):
        def fn(m, rng, ctx):
            segments = m.segments
            if not segments:
                segments.append(ContactSegment(end=Point(x=0.01), plan_id=getattr(m, "plan_id", 0)))
            change(segments[int(rng.integers(len(segments)))], rng, ctx)

        return fn

    return [
        ("segment start NaN", True, segment(_set("start.x", NAN))),
        ("segment end inf", True, segment(_set("end.y", INF))),
        ("segment status unknown", True, segment(_set("status", 7))),
        ("contact segment of zero length", True, segment(_zero_length)),
    ]


def _many_segments() -> Row:
    def fn(m, rng, ctx):
        m.segments = _cached(ctx, "segments", lambda: _segments(validate.MAX_SEGMENTS + 1))

    return ("segments past the limit", True, fn)


def _samples_rows() -> list[Row]:
    return [
        ("num_samples mismatched", True, lambda m, rng, ctx: setattr(m, "num_samples",
                                                                       m.num_samples + 1)),
        ("num_vertices 0", True, _set("num_vertices", 0)),
        ("samples NaN", True, lambda m, rng, ctx: setattr(m, "samples",
                                                           _poison(m.samples, NAN, rng))),
        ("samples empty", True, _set("samples", _floats(0))),
        ("samples 10^6", True, lambda m, rng, ctx: setattr(m, "samples", _floats(HUGE))),
        ("num_samples over limit", True, _set("num_samples", validate.MAX_SAMPLES + 1)),
        ("dropped_segments 10^6", True, _set("dropped_segments", array.array("I", [0] * HUGE))),
        ("dropped_segments beyond history", True, lambda m, rng, ctx: setattr(
            m, "dropped_segments", [m.history_length])),
    ]  # fmt: skip


def _plan_rows() -> list[Row]:
    def waypoint(value):
        return lambda m, rng, ctx: setattr(m.waypoints[int(rng.integers(len(m.waypoints)))],
                                           "y", value)  # fmt: skip

    def plan_id(choose):
        return _set("plan_id", lambda rng, ctx: choose(rng, ctx))

    return [
        ("waypoint NaN", True, waypoint(NAN)),
        ("waypoint inf", True, waypoint(INF)),
        ("waypoints empty", True, _set("waypoints", [])),
        ("one waypoint", True, lambda m, rng, ctx: setattr(m, "waypoints", m.waypoints[:1])),
        ("waypoints past the limit", True, lambda m, rng, ctx: setattr(m, "waypoints", _cached(
            ctx, "waypoints", lambda: _points(validate.MAX_WAYPOINTS + 1)))),
        ("load_direction not unit", True, _set("load_direction.y", -2.0)),
        ("load_direction NaN", True, _set("load_direction.x", NAN)),
        ("loading move against the load", True, _set("load_direction.y", 1.0)),
        ("decision unknown", True, _set("decision", 9)),
        ("force threshold 0", True, _set("contact_force_threshold", 0.0)),
        ("max_speed negative", True, _set("max_speed", -0.1)),
        ("max_speed inf", True, _set("max_speed", INF)),
        ("plan_id duplicated", False, plan_id(lambda rng, ctx: 1)),
        ("plan_id out of order", False, plan_id(lambda rng, ctx: int(rng.integers(1, 3)))),
        ("episode of the past", False, _set("episode", lambda rng, ctx: ctx.episodes[0])),
        ("episode unknown", False, _set("episode", lambda rng, ctx: int(rng.integers(3, 2**31)))),
    ]  # fmt: skip


def _report_rows() -> list[Row]:
    return [
        *_history_rows(),
        _many_segments(),
        ("outcome unknown", True, _set("outcome", 17)),
        ("stop_point NaN", True, _set("stop_point.x", NAN)),
        ("segment plan_id mismatched", True, _report_id(lambda ctx: 0, segments_too=False)),
        ("plan_id duplicated", False, _report_id(lambda ctx: ctx.reported_plans[-1])),
        ("plan_id out of order", False, _report_id(lambda ctx: ctx.reported_plans[-1] - 1)),
        ("episode of the past", False, _set("episode", lambda rng, ctx: ctx.episodes[0])),
        ("episode unknown", False, _set("episode", lambda rng, ctx: int(rng.integers(3, 2**31)))),
    ]  # fmt: skip


def _report_id(choose: Callable, segments_too: bool = True) -> Callable:
    """Set a report's plan_id (and its segments', as the executor does, unless told not to)."""

    def fn(m, rng, ctx):
        m.plan_id = choose(ctx)
        for s in m.segments if segments_too else ():
            s.plan_id = m.plan_id

    return fn


def _image_rows() -> list[Row]:
    return [
        *[(f"encoding {e!r}", True, _set("encoding", e)) for e in ("rgb8", "", "16UC3", "8UC1")],
        ("zero height", True, _set("height", 0)),
        ("zero width", True, _set("width", 0)),
        ("zero size, no data", True, _set_many(height=0, width=0, data=b"")),
        ("step shorter than a row", True, _set("step", 1)),
        ("data empty", True, _set("data", b"")),
        ("data 10^6 bytes", True, _set("data", bytes(HUGE))),
        ("pixels past the limit", True, _set_many(width=2**16, height=2**16)),
    ]  # fmt: skip


def _camera_info_rows() -> list[Row]:
    def k(values):
        return _set("k", lambda rng, ctx: values)

    return [
        ("K NaN", True, k([NAN] + [0.0] * 8)),
        ("K zero", True, k([0.0] * 9)),
        ("zero size", True, _set_many(width=0, height=0)),
        ("d 10^6 (unused)", False, _set("d", lambda rng, ctx: _floats(HUGE))),
    ]


def _status_rows() -> list[Row]:
    return [
        ("state unknown", True, _set("state", 200)),
        ("detail 10^6 characters", False, _set("detail", "x" * HUGE)),
        ("copy", False, lambda m, rng, ctx: None),
    ]


def _request_rows() -> list[Row]:
    return [
        ("episode 0", True, _set("episode", 0)),
        ("history_length 0", True, _set("history_length", 0)),
        ("history_length over limit", True, _set("history_length", validate.MAX_SEGMENTS + 1)),
        ("num_samples 2", True, _set("num_samples", 2)),
        ("num_samples over limit", True, _set("num_samples", validate.MAX_SAMPLES + 1)),
        ("nonce forged", False, _set("nonce", lambda rng, ctx: int(rng.integers(1, 2**62)))),
        ("history_length stale", False, _set("history_length", 1)),
        ("episode of the past", False, _set("episode", lambda rng, ctx: ctx.episodes[0])),
        ("episode unknown", False, _set("episode", lambda rng, ctx: int(rng.integers(3, 2**31)))),
    ]  # fmt: skip


def _episode_rows() -> list[Row]:
    return [
        ("episode 0", True, _set("data", 0)),
        ("episode duplicated", False, _set("data", lambda rng, ctx: ctx.episodes[-1])),
        ("episode out of order", False, _set("data", lambda rng, ctx: ctx.episodes[0])),
    ]


def table(type_name: str, frame_checked: bool) -> list[Row]:
    """The mutations of one message type ('pkg/msg/Name'); KeyError when there are none."""
    stamped = _stamp_rows(frame_checked)
    rows = {
        "tactile_dock_ros/msg/ShapeDistribution": lambda: [*_shape_rows(), *stamped],
        "tactile_dock_ros/msg/ContactHistory": lambda: [
            *_history_rows(), _many_segments(), *stamped,
            ("segments empty", False, _set("segments", [])),
        ],
        "tactile_dock_ros/msg/ShapeSamples": lambda: [*_samples_rows(), *stamped],
        "tactile_dock_ros/msg/DockingPlan": lambda: [*_plan_rows(), *stamped],
        "tactile_dock_ros/msg/ExecutionReport": lambda: [*_report_rows(), *stamped],
        "geometry_msgs/msg/PoseStamped": lambda: [
            *_vector_rows("pose", ("position",)),
            ("orientation zero", True, _set("pose.orientation.w", 0.0)),
            ("orientation NaN", True, _set("pose.orientation.z", NAN)),
            *stamped,
        ],
        "geometry_msgs/msg/WrenchStamped": lambda: [
            *_vector_rows("wrench", ("force", "torque")), *stamped],
        "geometry_msgs/msg/TwistStamped": lambda: [
            *_vector_rows("twist", ("linear", "angular")), *stamped],
        "sensor_msgs/msg/Image": lambda: [*_image_rows(), *stamped],
        "sensor_msgs/msg/CameraInfo": lambda: [*_camera_info_rows(), *stamped],
        "tactile_dock_ros/msg/EpisodeStatus": lambda: [*_status_rows(), *stamped],
        "tactile_dock_ros/msg/SampleRequest": lambda: [*_request_rows(), *stamped],
        "std_msgs/msg/UInt32": _episode_rows,
    }  # fmt: skip
    return rows[type_name]()


def mutations(type_name: str, base, count: int, rng: np.random.Generator, ctx: FuzzContext,
              frame_checked: bool) -> Iterator[Mutation]:  # fmt: skip
    """``count`` mutations of ``base``, cycling through the type's table (every kind is made
    ``count / len(table)`` times), random choices from ``rng``."""
    rows = table(type_name, frame_checked)
    for k in range(count):
        kind, malformed, fn = rows[k % len(rows)]
        msg = copy.deepcopy(base)
        out = fn(msg, rng, ctx)
        yield Mutation(kind, malformed, msg if out is None else out)


def valid_plan(episode: int, plan_id: int, header) -> DockingPlan:
    """A well-formed DOCK plan (down onto the mock terrain), the base of the plan mutations."""
    return DockingPlan(
        header=header, episode=episode, plan_id=plan_id, decision=DockingPlan.DOCK,
        waypoints=[Point(x=0.0, y=0.4), Point(x=0.0, y=0.2)],
        load_direction=Vector3(x=0.0, y=-1.0), contact_force_threshold=3.0,
        max_speed=0.1, docking_probability=0.5, objective=0.5, reason="fuzz",
    )  # fmt: skip


def valid_report(episode: int, plan_id: int, x: float, header) -> ExecutionReport:
    """A well-formed NO_CONTACT report with one free segment at plane x = ``x``."""
    segment = ContactSegment(header=header, start=Point(x=x, y=0.5), end=Point(x=x, y=0.4),
                             status=ContactSegment.FREE, plan_id=plan_id)  # fmt: skip
    return ExecutionReport(header=header, episode=episode, plan_id=plan_id,
                           outcome=ExecutionReport.NO_CONTACT, segments=[segment],
                           stop_point=Point(x=x, y=0.4), detail="fuzz")  # fmt: skip
