"""Test-run isolation for DDS: a random domain per run, localhost-only discovery.

Set at import time so that every process a test starts inherits the same isolated domain.
"""

import logging
import os
from pathlib import Path

import pytest

from tactile_dock_ros.tools.bringup import isolate_dds

TEST_DIR = Path(__file__).resolve().parent
REPO_ROOT = TEST_DIR.parent

# `pytest -n N` (make test): each worker on its own domain. Workers inherit the controller's
# environment, which this file set on import: worker k takes that domain + 1 + k (<= 232 for
# N <= 32), so no two processes of the run share one and no other run's domain is likely.
WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")  # gw0, gw1, ...
isolate_dds(keep_domain=WORKER.startswith("gw"))
if WORKER.startswith("gw"):
    os.environ["ROS_DOMAIN_ID"] = str(int(os.environ["ROS_DOMAIN_ID"]) + 1 + int(WORKER[2:]))
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(TEST_DIR / "fastdds_profile.xml")
# Child processes import the work-tree sources first, like pytest itself does.
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(REPO_ROOT), str(TEST_DIR), *filter(None, [os.environ.get("PYTHONPATH")])]
)


class LogRecords(logging.Handler):
    """Collects the records its loggers handle; ``text`` joins their messages."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if not any(r is record for r in self.records):  # once, also where it propagates
            self.records.append(record)

    @property
    def text(self) -> str:
        return "\n".join(r.getMessage() for r in self.records)


@pytest.fixture
def package_log():
    """Records logged by the package's loggers, caught by a handler on each of them.

    Not through propagation to the root logger as ``caplog`` is: launch_testing's pytest
    plugin (``colcon test`` on a ROS install) imports ``launch``, whose logger class turns
    ``propagate`` off for every logger created after it."""
    handler = LogRecords()
    loggers = [logging.getLogger("tactile_dock_ros")] + [
        logger
        for name, logger in list(logging.Logger.manager.loggerDict.items())
        if name.startswith("tactile_dock_ros.") and isinstance(logger, logging.Logger)
    ]
    for logger in loggers:
        logger.addHandler(handler)
    try:
        yield handler
    finally:
        for logger in loggers:
            logger.removeHandler(handler)
