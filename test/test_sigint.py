"""SIGINT stops a node through rclpy's shutdown, not by an exception thrown into whatever
Python code runs (common.stop_cleanly_on_sigint); a second SIGINT interrupts at once."""

import subprocess
import sys

SCRIPT = """
import os, signal, time
import rclpy
from tactile_dock_ros.nodes.common import stop_cleanly_on_sigint
stop_cleanly_on_sigint()
rclpy.init()
os.kill(os.getpid(), signal.SIGINT)
deadline = time.monotonic() + 2.0
while rclpy.ok() and time.monotonic() < deadline:
    sum(range(100))  # Python code runs: a KeyboardInterrupt would surface here
print("first SIGINT: context ok", rclpy.ok(), flush=True)
try:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(10.0)
    print("second SIGINT: not interrupted")
except KeyboardInterrupt:
    print("second SIGINT: KeyboardInterrupt")
"""


def test_the_first_sigint_shuts_down_the_context_the_second_interrupts():
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=60.0
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "first SIGINT: context ok False",
        "second SIGINT: KeyboardInterrupt",
    ], done.stderr
