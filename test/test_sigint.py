"""SIGINT and SIGTERM stop a node between callbacks, not by an exception thrown into whatever
Python code runs, and ``common.run`` calls the node's ``on_shutdown`` while its context is
still valid (common.StopSignals); a second signal interrupts at once."""

import subprocess
import sys

import pytest

SCRIPT = """
import os, signal, sys, time
from rclpy.node import Node
from std_msgs.msg import Header
from tactile_dock_ros.nodes.common import run

SIGNAL, COUNT = getattr(signal, sys.argv[1]), int(sys.argv[2])


class Busy(Node):
    def __init__(self):
        super().__init__("busy")
        self.pub = self.create_publisher(Header, "h", 1)
        self.timer = self.create_timer(0.01, self.on_timer)

    def on_timer(self):
        self.timer.cancel()
        try:
            for _ in range(COUNT):
                os.kill(os.getpid(), SIGNAL)
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline:
                sum(range(100))  # Python code runs: a KeyboardInterrupt would surface here
            print("callback finished", flush=True)
        except KeyboardInterrupt:
            print("callback interrupted", flush=True)
            raise

    def on_shutdown(self):
        self.pub.publish(Header(frame_id="stop"))  # raises once the context is shut down
        print("on_shutdown: context ok", self.context.ok(), flush=True)


print("exit", run(Busy, []), flush=True)
"""


def _run(signal_name: str, count: int) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, signal_name, str(count)],
        capture_output=True,
        text=True,
        timeout=60.0,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


@pytest.mark.parametrize("signal_name", ["SIGINT", "SIGTERM"])
def test_the_first_signal_ends_the_spin_after_the_callback_and_runs_on_shutdown(signal_name):
    assert _run(signal_name, 1) == [
        "callback finished",
        "on_shutdown: context ok True",
        "exit 0",
    ]


def test_a_second_signal_interrupts_and_on_shutdown_still_runs():
    assert _run("SIGINT", 2) == [
        "callback interrupted",
        "on_shutdown: context ok True",
        "exit 0",
    ]
