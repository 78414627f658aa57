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
from collections.abc import Iterable, Iterator
from pathlib import Path

from tactile_dock_ros.tools import launch_xml

PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # source tree: launch/, config/, scripts/
LAUNCH_FILE = PACKAGE_ROOT / "launch" / "tactile_dock.launch.xml"


def isolate_dds(keep_domain: bool = False) -> None:
    """Put this process and those it starts on a random DDS domain (100-200), discovering peers
    on this machine only: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (Iron and later) and, on Humble,
    ``ROS_LOCALHOST_ONLY``. ``keep_domain`` keeps a ``ROS_DOMAIN_ID`` the caller already set."""
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
    """SIGINT (rclpy shuts down cleanly), then SIGKILL whatever is still running."""
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
