"""Package metadata and code hygiene: package.xml is valid and declares what the code imports."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package
from conftest import REPO_ROOT

# Third-party import name -> rosdep key declared in package.xml.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "shapely": "python3-shapely",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "cv2": "python3-opencv",
    "open3d": "python3-open3d-pip",
    "tmg_hmc": "python3-tmg-hmc-pip",
    "rosbags": "python3-rosbags-pip",
    "mcap": "python3-mcap-pip",
    "mcap_ros2": "python3-mcap-ros2-support-pip",
    "pytest": "python3-pytest",
    "hypothesis": "python3-hypothesis",
    "catkin_pkg": "python3-catkin-pkg",
    "rclpy": "rclpy",
    "ament_index_python": "ament_index_python",
    "builtin_interfaces": "builtin_interfaces",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "geometry_msgs": "geometry_msgs",
    "sensor_msgs": "sensor_msgs",
    "visualization_msgs": "visualization_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "rcl_interfaces": "rcl_interfaces",
    "launch": "launch",
    "launch_testing": "launch_testing",
}
LOCAL = {"tactile_dock_ros"} | {p.stem for p in (REPO_ROOT / "test").glob("*.py")}


def _top_level_imports(root: Path) -> set[str]:
    names = set()
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names.add(node.module.split(".")[0])
    return names - LOCAL - set(sys.stdlib_module_names)


@pytest.fixture(scope="module")
def package():
    return parse_package(str(REPO_ROOT / "package.xml"))


def test_package_xml_is_valid_format_3(package):
    package.validate()
    assert package.name == "tactile_dock_ros"
    assert package.package_format == 3
    assert package.get_build_type() == "ament_cmake"


@pytest.mark.parametrize(
    ("tree", "kinds"),
    [("tactile_dock_ros", ("exec_depends",)), ("test", ("exec_depends", "test_depends"))],
)
def test_imports_are_declared(package, tree, kinds):
    """Code under tactile_dock_ros/ needs exec_depends; tests may also use test_depends."""
    declared = {d.name for kind in kinds for d in getattr(package, kind)}
    imported = _top_level_imports(REPO_ROOT / tree)
    unknown = imported - ROSDEP_KEYS.keys()
    assert not unknown, f"add a rosdep key for {unknown} to ROSDEP_KEYS and package.xml"
    missing = {ROSDEP_KEYS[name] for name in imported} - declared
    assert not missing, f"package.xml lacks {kinds} {missing}"


def test_ruff_passes_on_the_whole_tree():
    ruff = [sys.executable, "-m", "ruff"]
    check = subprocess.run([*ruff, "check", "."], cwd=REPO_ROOT, capture_output=True, text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    fmt = subprocess.run(
        [*ruff, "format", "--check", "."], cwd=REPO_ROOT, capture_output=True, text=True
    )
    assert fmt.returncode == 0, fmt.stdout + fmt.stderr
