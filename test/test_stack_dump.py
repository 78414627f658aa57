"""A node asked for its stacks (SIGUSR1) writes them to its log and keeps running."""

import subprocess
import sys
import time

import pytest

from tactile_dock_ros.tools import bringup

pytestmark = pytest.mark.dds


def _wait_for(log, text, timeout_s=120.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.exists() and text in log.read_text(errors="replace"):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.skipif(bringup.STACK_DUMP_SIGNAL is None, reason="no SIGUSR1 on this platform")
def test_a_running_node_dumps_its_stacks_and_goes_on(tmp_path):
    with bringup.running({"profile": "mock"}, tmp_path, only={"inference"}) as processes:
        log = tmp_path / "inference.log"
        assert _wait_for(log, "sampler kernels ready"), log.read_text(errors="replace")
        # that line comes from the node's constructor: until the node spins a dump shows the
        # constructor's frames, so ask again (each dump must come) until the spin loop shows
        deadline = time.monotonic() + 60.0
        while True:
            assert bringup.dump_stacks(processes, tmp_path) == ["inference"]
            text = log.read_text(errors="replace")
            if "spin" in text or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert bringup.STACK_MARKER in text and "spin" in text  # the executor's spin loop
        assert processes["inference"].poll() is None  # SIGUSR1's default would have ended it
        assert bringup.dump_stacks(processes, tmp_path) == ["inference"]  # again, at will
    assert processes["inference"].returncode == 0  # the SIGINT of the end of the block


def test_no_signal_goes_to_a_process_that_has_ended(tmp_path):
    (tmp_path / "done.log").write_text("")
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    assert bringup.dump_stacks({"done": done}, tmp_path, timeout_s=0.5) == []
