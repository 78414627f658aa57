"""The CMake project installs like a colcon build would: messages, Python package, share/."""

import os
import shutil
import subprocess
import sys

import pytest
from conftest import REPO_ROOT


def _installed_share() -> str | None:
    """This package's share/ under any AMENT_PREFIX_PATH entry (None: not installed)."""
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        return get_package_share_directory("tactile_dock_ros")
    except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH not set
        return None


@pytest.mark.timeout(600)
def test_full_install_has_messages_python_package_and_share(tmp_path):
    if _installed_share() is None:
        pytest.skip(
            "tactile_dock_ros is installed under no AMENT_PREFIX_PATH entry "
            f"({os.environ.get('AMENT_PREFIX_PATH') or 'unset'}): run through `make test` or "
            "`colcon test`"
        )
    # Every prefix (colcon puts the package's own install first, the ROS prefix after it).
    prefixes = [p for p in os.environ["AMENT_PREFIX_PATH"].split(os.pathsep) if p]
    # A copy outside the work tree: the venv inside the work tree would sit in the source dir.
    src = tmp_path / "src"
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    for name in files:
        if (REPO_ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO_ROOT / name, src / name)
    prefix = tmp_path / "install"
    bins = [os.path.join(p, "bin") for p in prefixes if os.path.isdir(os.path.join(p, "bin"))]
    env = {**os.environ, "PATH": os.pathsep.join([*bins, os.environ["PATH"]])}
    configure = [
        "cmake",
        "-S",
        str(src),
        "-B",
        str(tmp_path / "build"),
        "-Wno-dev",
        f"-DCMAKE_PREFIX_PATH={';'.join(prefixes)}",
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        "-DBUILD_TESTING=OFF",
    ]
    build = ["cmake", "--build", str(tmp_path / "build"), "-j2"]
    for cmd in (configure, build, ["cmake", "--install", str(tmp_path / "build")]):
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert done.returncode == 0, f"{' '.join(cmd)}:\n{done.stdout[-3000:]}{done.stderr[-3000:]}"

    site = prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    probe = (
        "import tactile_dock_ros, tactile_dock_ros.core.problems as p\n"
        "from tactile_dock_ros.msg import ContactSegment, DockingPlan\n"
        "from tactile_dock_ros.action import Dock\n"
        "from tactile_dock_ros.srv import EvaluateHold\n"
        "from ament_index_python.packages import get_package_share_directory as share\n"
        "print(p.__file__); print(share('tactile_dock_ros'))\n"
    )
    run_env = {
        **env,
        "PYTHONPATH": str(site),
        "AMENT_PREFIX_PATH": os.pathsep.join([str(prefix), *prefixes]),
    }
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=tmp_path, env=run_env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    module_file, share_dir = out.stdout.split()
    assert module_file.startswith(str(site))
    assert share_dir == str(prefix / "share" / "tactile_dock_ros")
    assert (prefix / "share" / "tactile_dock_ros" / "package.xml").is_file()
