"""The Makefile's developer setup: what reinstalls the package's share files into the venv."""

import os
import shutil
import subprocess

import pytest
from conftest import REPO_ROOT


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_a_changed_share_file_reinstalls_the_share_directory():
    """Launch files and tools find ``config/`` and ``launch/`` through the venv's share
    directory: every file installed there is a prerequisite of the install step, so editing a
    profile or refitting the terrain classes reinstalls them (a stale share copy ran the old
    class library from another working directory)."""
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}
    database = subprocess.run(
        ["make", "-pn", "setup"], cwd=REPO_ROOT, env=env, capture_output=True, text=True
    ).stdout
    rules = [  # rule lines only: with a stale stamp, -n also prints "touch .venv/.stamps/msgs"
        line for line in database.splitlines()
        if ":" in line and line.split(":")[0].endswith("stamps/msgs")
    ]  # fmt: skip
    prerequisites = {p for line in rules for p in line.split(":", 1)[1].split()}
    shared = {
        str(path.relative_to(REPO_ROOT))
        for folder in ("launch", "config", "security", "scripts")
        for path in (REPO_ROOT / folder).iterdir()
        if path.is_file() and not path.name.startswith(".")  # .gitkeep: not a share file
    }
    assert "config/terrain_classes.npz" in shared and "launch/tactile_dock.launch.xml" in shared
    assert shared <= prerequisites, sorted(shared - prerequisites)
