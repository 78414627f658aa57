"""The CMake project installs like a colcon build would: messages, Python package, share/."""

import os
import shutil
import subprocess
import sys

import pytest
from conftest import REPO_ROOT


@pytest.mark.timeout(600)
def test_full_install_has_messages_python_package_and_share(tmp_path):
    venv = os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)[0]
    if not venv or not os.path.isdir(os.path.join(venv, "share", "ament_cmake")):
        pytest.skip("AMENT_PREFIX_PATH does not point at a ROS 2 prefix (run through `make test`)")
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
    env = {**os.environ, "PATH": f"{venv}/bin:{os.environ['PATH']}"}
    configure = [
        "cmake",
        "-S",
        str(src),
        "-B",
        str(tmp_path / "build"),
        "-Wno-dev",
        f"-DCMAKE_PREFIX_PATH={venv}",
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        "-DBUILD_TESTING=OFF",
    ]
    for cmd in (configure, ["cmake", "--build", str(tmp_path / "build"), "-j2"]):
        subprocess.run(cmd, env=env, check=True, capture_output=True)
    subprocess.run(["cmake", "--install", str(tmp_path / "build")], check=True, capture_output=True)

    site = prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    probe = (
        "import tactile_dock_ros, tactile_dock_ros.core.problems as p\n"
        "from tactile_dock_ros.msg import ContactSegment, DockingPlan\n"
        "from ament_index_python.packages import get_package_share_directory as share\n"
        "print(p.__file__); print(share('tactile_dock_ros'))\n"
    )
    run_env = {**env, "PYTHONPATH": str(site), "AMENT_PREFIX_PATH": f"{prefix}:{venv}"}
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=tmp_path, env=run_env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    module_file, share_dir = out.stdout.split()
    assert module_file.startswith(str(site))
    assert share_dir == str(prefix / "share" / "tactile_dock_ros")
    assert (prefix / "share" / "tactile_dock_ros" / "package.xml").is_file()
