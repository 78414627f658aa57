"""Glue shared by every node: plane-frame parameters, stamped headers, guarded subscriptions,
main."""

from __future__ import annotations

import faulthandler
import importlib
import inspect
import os
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable

import numpy as np
import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_msgs.msg import Header

from tactile_dock_ros.execution.types import UNIT_TOLERANCE, PlaneFrame
from tactile_dock_ros.nodes import validate
from tactile_dock_ros.nodes.params import Param
from tactile_dock_ros.nodes.validate import MessageError

# Seconds between two log lines of one cause of malformed input on one topic.
MALFORMED_LOG_PERIOD_S = 10.0

# The docking plane in the arm base frame (tf2 is not used; docs/nodes.md, "Running it").
PLANE_FRAME_ID = Param("plane_frame_id", "dock_plane", "frame id stamped on plane-frame messages")
PLANE_TABLE = [
    PLANE_FRAME_ID,
    Param("base_frame_id", "base_link", "arm base frame of poses, wrenches and commands"),
    Param(
        "plane_origin", [0.0, 0.0, 0.0], "plane origin in the base frame", "m", -100, 100, length=3
    ),
    Param(
        "plane_x_axis", [1.0, 0.0, 0.0], "plane x axis in the base frame", "unit", -1, 1, length=3
    ),
    Param(
        "plane_y_axis",
        [0.0, 0.0, 1.0],
        "plane y axis (up) in the base frame",
        "unit",
        -1,
        1,
        length=3,
    ),
]


def workspace_box(low: list[float], high: list[float], whose: str) -> list[Param]:
    """``workspace_min`` / ``workspace_max``: a box of the docking plane (x, y), metres, each
    corner coordinate within +-100 m."""
    return [
        Param(
            f"workspace_{end}",
            corner,
            f"{whose}, {side} corner (plane x, y)",
            "m",
            -100,
            100,
            length=2,
        )
        for end, corner, side in (("min", low, "lower"), ("max", high, "upper"))
    ]


# The load both the planner (docking) and inference (the slides it conditions on) assume.
LOAD_DIRECTION = Param(
    "load_direction",
    [0.0, -1.0],
    "unit load direction f_load in the plane (give planner, inference and perception the same)",
    "",
    -1,
    1,
    length=2,
)


def unit_load(values) -> np.ndarray:
    """The ``load_direction`` parameter as a (2,) array; ValueError unless a unit vector."""
    load = np.asarray(values.load_direction, float)
    if abs(np.linalg.norm(load) - 1.0) > UNIT_TOLERANCE:
        raise ValueError(f"parameter load_direction must be a unit vector, got {load}")
    return load


# Captured holds kept by perception, and their priors by the planner and inference (one bound).
MAX_HOLDS = Param("max_holds", 8, "captured holds kept (the oldest is dropped)", "", 1, 1000)


def plane_frame(values) -> PlaneFrame:
    return PlaneFrame(values.plane_origin, values.plane_x_axis, values.plane_y_axis)


def header(node: Node, frame_id: str) -> Header:
    """A header stamped with the node clock (ROS time when use_sim_time is set)."""
    return Header(stamp=node.get_clock().now().to_msg(), frame_id=frame_id)


def now_seconds(node: Node) -> float:
    """The node clock in seconds (ROS time when use_sim_time is set)."""
    return node.get_clock().now().nanoseconds * 1e-9


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time -> seconds."""
    return stamp.sec + 1e-9 * stamp.nanosec


class MalformedLog:
    """Counts dropped messages per topic and logs each cause (``validate.cause``) at most once
    per ``period_s`` seconds, saying how many like it were dropped in between."""

    def __init__(self, logger, period_s: float = MALFORMED_LOG_PERIOD_S, clock=time.monotonic):
        self.logger, self.period_s, self.clock = logger, period_s, clock
        self.dropped: Counter[str] = Counter()  # topic -> messages dropped
        self._causes: dict[tuple[str, str], list] = {}  # (topic, cause) -> [next log, quiet]

    def drop(self, topic: str, err: MessageError) -> None:
        self.dropped[topic] += 1
        key, now = (topic, validate.cause(err)), self.clock()
        entry = self._causes.setdefault(key, [now, 0])
        if now < entry[0]:
            entry[1] += 1
            return
        more = f" ({entry[1]} more dropped for this cause since)" if entry[1] else ""
        self.logger.error(f"dropped {topic} message: {err}{more}")
        entry[:] = [now + self.period_s, 0]


def subscribe(
    node: Node,
    msg_type,
    topic: str,
    callback: Callable,
    profile,
    frame_id=None,
    callback_group=None,
):
    """``node.create_subscription`` behind the guard every subscription of the suite has: the
    serialized size is checked (``validate.max_message_bytes``) before the message is
    deserialized, then the stamp (and the frame, when ``frame_id`` is given), then ``callback``
    runs; a :class:`MessageError` from any drops the message, counted and logged by
    ``node.malformed`` under the resolved topic name; ``callback_group`` as rclpy's."""
    if not hasattr(node, "malformed"):
        node.malformed = MalformedLog(node.get_logger())
    stamped = "header" in msg_type.get_fields_and_field_types()
    limit = validate.max_message_bytes(msg_type)

    def guarded(raw: bytes) -> None:
        try:
            validate.check_size(name, len(raw), limit)
            msg = deserialize_message(raw, msg_type)
            if stamped:
                now_ns = node.get_clock().now().nanoseconds
                validate.check_stamp(name, msg.header.stamp, now_ns)
                if frame_id is not None:
                    validate.check_frame(name, msg, frame_id)
            callback(msg)
        except MessageError as err:
            node.malformed.drop(name, err)

    subscription = node.create_subscription(
        msg_type, topic, guarded, profile, callback_group=callback_group, raw=True
    )
    name = subscription.topic_name
    return subscription


def node_class(executable: str) -> type[Node]:
    """The one Node subclass defined by ``tactile_dock_ros.nodes.<executable>`` (in-process
    runs of a launch file's node: tests, the fuzzer)."""
    module = importlib.import_module(f"tactile_dock_ros.nodes.{executable}")
    (cls,) = [
        c
        for _, c in inspect.getmembers(module, inspect.isclass)
        if issubclass(c, Node) and c.__module__ == module.__name__
    ]
    return cls


class Stopwatch:
    """Wall-clock seconds of a block: ``with Stopwatch() as sw: ...; sw.seconds``."""

    def __enter__(self) -> Stopwatch:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = time.perf_counter() - self._t0


STACK_DUMP_SIGNAL = getattr(signal, "SIGUSR1", None)  # None on Windows


def dump_stacks_on_signal() -> None:
    """Make ``kill -USR1 <pid>`` print the Python stack of every thread to stderr (the node's
    log), also while the node computes in numpy or compiled code; the node is not disturbed.

    Decision: a node that goes silent on the robot (a sampler that runs for a minute) must be
    diagnosable where it hangs, without a debugger or a restart that loses the state."""
    if STACK_DUMP_SIGNAL is not None:
        faulthandler.register(STACK_DUMP_SIGNAL, file=sys.stderr, all_threads=True)


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
SHUTDOWN_HOOK = "on_shutdown"  # a node's method run by ``run`` as it exits, context still valid


class StopSignals:
    """The first SIGINT or SIGTERM completes ``future`` and wakes ``executor`` at once, a second
    one raises KeyboardInterrupt in the main thread.

    Install before ``rclpy.init(signal_handler_options=NO)``. Decision: rclpy's own handlers shut
    the context down inside the signal, so nothing can be published afterwards: the executor
    node could not stop the arm on SIGTERM (``ros2 launch`` sends it to a node that ignores
    SIGINT; systemd and docker send it first). Here the context stays valid until ``run`` has
    called the node's ``on_shutdown``. Python runs a signal handler only between bytecodes of
    the main thread, which waits inside rcl: the C-level handler's wakeup fd lets a helper
    thread wake the executor. Python's default SIGINT handler raised KeyboardInterrupt wherever
    the main thread was, also half-way through an rclpy ``Task``'s constructor, whose
    ``__del__`` then printed a traceback into the node log (the fuzz check counts tracebacks);
    so the first signal only asks, and a node busy in a long callback (a sampler) finishes it;
    a second signal (``bringup.stop`` sends SIGKILL after its timeout) interrupts it."""

    def __init__(self) -> None:
        self.future: Future = Future()
        self.executor: Executor | None = None
        self.received: list[int] = []
        self.cleaning_up = False
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        for signum in STOP_SIGNALS:
            signal.signal(signum, self._on_signal)
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        threading.Thread(target=self._watch, args=(read_fd,), name="stop", daemon=True).start()

    def _on_signal(self, signum, frame) -> None:
        self.received.append(signum)
        if len(self.received) > 1 and not self.cleaning_up:
            raise KeyboardInterrupt

    def clean_up(self) -> None:
        """From here on signals are only counted: ``run``'s cleanup (the node's stop command,
        destroying it) is short and bounded, and a second Ctrl-C (a terminal and ``ros2
        launch`` both forward one) must not cut it short; SIGKILL still ends the process."""
        self.cleaning_up = True

    def _watch(self, read_fd: int) -> None:
        while not self.future.done():
            if set(os.read(read_fd, 64)) & set(STOP_SIGNALS):
                self.future.set_result(True)
                if self.executor is not None:
                    self.executor.wake()


def run_shutdown_hook(node: Node) -> None:
    """Call ``node.on_shutdown()`` if the node defines it and its context is still valid (an
    exception in it is logged: the node is going away regardless)."""
    hook = getattr(node, SHUTDOWN_HOOK, None)
    if not callable(hook) or not node.context.ok():
        return
    try:
        hook()
    except Exception as err:  # the exit path must go on
        node.get_logger().error(f"{SHUTDOWN_HOOK} failed: {err!r}")


def run(
    node_class: type[Node],
    args: list[str] | None = None,
    executor: Callable[[], Executor] = SingleThreadedExecutor,
) -> int:
    """Console entry point: init, spin with ``executor()`` until SIGINT or SIGTERM
    (``StopSignals``; the node's ``before_spin``, if it has one, is called first in the thread
    that spins), then call the node's ``on_shutdown`` if it has one (after the executor
    stopped, so nothing the node publishes follows it; also when a callback raised), clean up;
    parameter errors exit 2. SIGUSR1 prints every thread's Python stack to stderr and the node
    goes on (``dump_stacks_on_signal``)."""
    dump_stacks_on_signal()
    stop = StopSignals()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = spinner = None
    try:
        node = node_class()
        spinner = stop.executor = executor()
        spinner.add_node(node)
        if hasattr(node, "before_spin"):  # in the thread that spins (not in in-process tests)
            node.before_spin()
        spinner.spin_until_future_complete(stop.future)
    except ValueError as err:  # invalid parameters: say which and stop
        print(f"{node_class.__name__}: {err}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # A message rclpy was converting when the context shut down surfaces as this (seen
        # under fuzzing): the shutdown; anything else is a fault.
        if rclpy.ok():
            raise
    finally:
        stop.clean_up()
        if spinner is not None:
            spinner.shutdown()
        if node is not None:
            run_shutdown_hook(node)
            dropped = getattr(node, "malformed", None)
            if dropped is not None and dropped.dropped:
                counts = ", ".join(f"{t} {n}" for t, n in sorted(dropped.dropped.items()))
                node.get_logger().info(f"malformed messages dropped: {counts}")
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
