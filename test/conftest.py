"""Test-run isolation for DDS: a random domain per run, localhost-only discovery.

Set at import time so that every process a test starts inherits the same isolated domain.
"""

import os
from pathlib import Path

from tactile_dock_ros.tools.bringup import isolate_dds

TEST_DIR = Path(__file__).resolve().parent
REPO_ROOT = TEST_DIR.parent

isolate_dds()
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(TEST_DIR / "fastdds_profile.xml")
# Child processes import the work-tree sources first, like pytest itself does.
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(REPO_ROOT), str(TEST_DIR), *filter(None, [os.environ.get("PYTHONPATH")])]
)
