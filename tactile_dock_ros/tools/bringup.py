"""Start the processes a launch file declares, without the launch packages (tests, make demo).

Each node runs its ``scripts/`` executable with the launch file's parameters and remappings
(``tools.launch_xml``); output goes to ``<log_dir>/<node>.log``. ``ros2 launch`` does the same
on a ROS 2 install.
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from tactile_dock_ros.nodes.common import STACK_DUMP_SIGNAL
from tactile_dock_ros.tools import launch_xml

PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # source tree: launch/, config/, scripts/
LAUNCH_FILE = PACKAGE_ROOT / "launch" / "tactile_dock.launch.xml"


def isolate_dds(keep_domain: bool = False) -> None:
    """Put this process and those it starts on a random DDS domain (100-200), discovering peers
    on this machine only: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (Iron and later) and, on Humble,
    ``ROS_LOCALHOST_ONLY``. ``keep_domain`` keeps a ``ROS_DOMAIN_ID`` the caller already set.
    Decision: the domain comes from the OS's entropy, not a seeded generator: runs started at
    the same time (pytest workers, CI jobs) must not share one, and no result depends on it."""
    if not (keep_domain and "ROS_DOMAIN_ID" in os.environ):
        os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(100, 200))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if os.environ.get("ROS_DISTRO") == "humble":
        os.environ["ROS_LOCALHOST_ONLY"] = "1"


def nodes(arguments: dict[str, str]) -> list[launch_xml.NodeLaunch]:
    return launch_xml.parse(LAUNCH_FILE, {"tactile_dock_ros": PACKAGE_ROOT}, arguments)


@contextlib.contextmanager
def running(
    arguments: dict[str, str], log_dir: Path, only: Iterable[str] | None = None
) -> Iterator[dict[str, subprocess.Popen]]:
    """Run the launch file's nodes (all, or those named in ``only``) until the block exits.

    The nodes' journals go to ``<log_dir>/state`` unless ``arguments`` name a state_directory,
    so that runs never resume each other's episodes. The yielded dict maps node names to
    processes; a process put in it (``respawn``) is stopped at the end too."""
    log_dir = Path(log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    arguments = _with_state(arguments, log_dir)
    processes: dict[str, subprocess.Popen] = {}
    try:
        for node in nodes(arguments):
            if only is None or node.name in set(only):
                processes[node.name] = start(node, log_dir)
        yield processes
    finally:
        stop(processes.values())


def start(node: launch_xml.NodeLaunch, log_dir: Path, log_mode: str = "w") -> subprocess.Popen:
    """Start one node's process; its output goes to ``<log_dir>/<node>.log``."""
    # The scripts import the package of this source tree, as the work tree's tests do.
    path = [str(PACKAGE_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(path), **node.environment}
    with open(Path(log_dir) / f"{node.name}.log", log_mode) as log:
        return subprocess.Popen(
            node.command(PACKAGE_ROOT / "scripts", log_dir, sys.executable),
            stdout=log,
            stderr=subprocess.STDOUT,
            env=environment,
        )


def respawn(
    processes: dict[str, subprocess.Popen], name: str, arguments: dict[str, str], log_dir: Path
) -> None:
    """Start node ``name`` again with the launch settings of ``running(arguments, log_dir)``
    (after it crashed or was killed: fault-injection tests); its log is appended to."""
    (node,) = [n for n in nodes(_with_state(arguments, log_dir)) if n.name == name]
    processes[name] = start(node, log_dir, log_mode="a")


def _with_state(arguments: dict[str, str], log_dir: Path) -> dict[str, str]:
    return {"state_directory": str(Path(log_dir) / "state"), **arguments}


def stop(processes: Iterable[subprocess.Popen], timeout_s: float = 10.0) -> None:
    """SIGINT (a node stops between callbacks: ``common.StopSignals``), then SIGKILL whatever
    is still running."""
    processes = list(processes)
    for p in processes:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in processes:
        try:
            p.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


STACK_MARKER = "most recent call first"  # faulthandler's header of each thread's stack


def dump_stacks(
    processes: dict[str, subprocess.Popen], log_dir: Path, timeout_s: float = 5.0
) -> list[str]:
    """Ask each running node for its threads' Python stacks (SIGUSR1, which every node's
    ``common.run`` registers) and wait until its log shows them; returns the nodes that did.

    For a node gone silent: where it computes is then in ``<log_dir>/<node>.log``."""
    sizes = {}
    for name, p in processes.items():
        log = Path(log_dir) / f"{name}.log"
        if STACK_DUMP_SIGNAL is not None and p.poll() is None and log.exists():
            sizes[name] = log.stat().st_size
            p.send_signal(STACK_DUMP_SIGNAL)
    dumped: list[str] = []
    deadline = time.monotonic() + timeout_s
    while sizes and time.monotonic() < deadline:
        for name in list(sizes):
            with open(Path(log_dir) / f"{name}.log", errors="replace") as log:
                log.seek(sizes[name])
                if STACK_MARKER in log.read():
                    dumped.append(name)
                    del sizes[name]
        time.sleep(0.05)
    return dumped
