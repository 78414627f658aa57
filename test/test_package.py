"""Package metadata and code hygiene: package.xml declares exactly what the package uses, with
keys rosdep can resolve; every pin is needed; `make` builds Kilted and Jazzy apart; the pinned
pytest loads launch_testing's plugin; ruff is clean."""

import ast
import importlib.metadata as metadata
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package
from conftest import REPO_ROOT
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

# Third-party import name -> rosdep key declared in package.xml.
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "numba": "python3-numba",
    "scipy": "python3-scipy",
    "shapely": "python3-shapely",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "cv2": "python3-opencv",
    "rosbags": "python3-rosbags-pip",
    "pytest": "python3-pytest",
    "hypothesis": "python3-hypothesis",
    "catkin_pkg": "python3-catkin-pkg",
    "packaging": "python3-packaging",
    "rclpy": "rclpy",
    "ament_index_python": "ament_index_python",
    "builtin_interfaces": "builtin_interfaces",
    "action_msgs": "action_msgs",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "geometry_msgs": "geometry_msgs",
    "sensor_msgs": "sensor_msgs",
    "visualization_msgs": "visualization_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "rcl_interfaces": "rcl_interfaces",
    "lifecycle_msgs": "lifecycle_msgs",
    "launch": "launch",
    "launch_testing": "launch_testing",
}
# Imported, but rosdistro has no rosdep key for it: installed from requirements-pip.txt and not
# declared. tmg_hmc is only the baseline of `bench sampling` (which has --skip-tmg); mcap and
# mcap_ros2 only read bags back in test_replay.py (others' MCAP reader).
PIP_ONLY = {
    "tmg_hmc": "tmg-hmc",
    "mcap": "mcap",
    "mcap_ros2": "mcap-ros2-support",
}
# Declared dependencies used by something other than a Python import: (kind, files, pattern).
OTHER_USES = {
    "ament_cmake": ("buildtool_depends", "CMakeLists.txt", r"find_package\(ament_cmake "),
    "ament_cmake_python": ("buildtool_depends", "CMakeLists.txt", r"_ament_cmake_python_"),
    "rosidl_default_generators": ("buildtool_depends", "CMakeLists.txt", r"rosidl_generate_"),
    "rosidl_default_runtime": ("exec_depends", "CMakeLists.txt", r"rosidl_default_runtime"),
    # the generated Dock action's goal/result services and status topic are action_msgs types
    "action_msgs": ("exec_depends", "CMakeLists.txt", r"DEPENDENCIES .*action_msgs"),
    "launch_xml": ("exec_depends", "launch/*.launch.xml", r"<launch>"),
    "launch_ros": ("exec_depends", "launch/*.launch.xml", r"<node |\$\(find-pkg-share "),
    "ament_cmake_pytest": ("test_depends", "CMakeLists.txt", r"ament_add_pytest_test\("),
    "launch_testing_ament_cmake": ("test_depends", "CMakeLists.txt", r"add_launch_test\("),
    "python3-ruff-pip": ("test_depends", "test/test_package.py", r'"-m", "ruff"\]'),
}
# Every key package.xml may use. System keys of ros/rosdistro's rosdep/*.yaml, checked by name:
# merged rosdistro PRs added python3-rosbags-pip (37795), python3-ruff-pip (39543),
# python3-hypothesis (23334), python3-shapely (25369), python3-packaging (23363),
# python3-catkin-pkg (18093), python3-yaml (15377); python3-numba resolves to apt on noble; numpy,
# scipy, matplotlib, opencv and pytest are keys of ROS 2's own packages. There is none for open3d
# or tmg-hmc. ROS keys: packages released in Humble, Jazzy and Kilted. `rosdep` cannot run here
# (`rosdep init` fetches its sources list from GitHub): test_rosdep_resolves_every_key runs it
# where it is initialized.
SYSTEM_KEYS = {
    "python3-numpy", "python3-scipy", "python3-shapely", "python3-yaml", "python3-matplotlib",
    "python3-opencv", "python3-rosbags-pip", "python3-pytest", "python3-hypothesis",
    "python3-catkin-pkg", "python3-packaging", "python3-ruff-pip", "python3-numba",
}  # fmt: skip
ROS_KEYS = {
    "action_msgs", "ament_cmake", "ament_cmake_python", "ament_cmake_pytest", "ament_index_python",
    "builtin_interfaces", "diagnostic_msgs", "geometry_msgs", "launch", "launch_ros",
    "launch_testing", "launch_testing_ament_cmake", "launch_xml", "lifecycle_msgs",
    "rcl_interfaces", "rclpy",
    "rosidl_default_generators", "rosidl_default_runtime", "sensor_msgs", "std_msgs", "std_srvs",
    "visualization_msgs",
}  # fmt: skip
# Pinned in requirements*.txt though nothing imports them: pytest's timeout plugin (pytest.ini),
# its process pool (pytest-xdist: `make test` runs -n TEST_WORKERS) and the linter
# test_ruff_passes_on_the_whole_tree runs. ROS wheels (ros-*) count as used: the
# message build and rclpy need them without importing them by name.
TOOLS = {"pytest-timeout", "pytest-xdist", "ruff"}
# The layers that run without ROS (setup.py's library): no rclpy, no messages, no nodes.
ROS_FREE = ("core", "perception", "execution")
LOCAL = {"tactile_dock_ros"} | {p.stem for p in (REPO_ROOT / "test").glob("*.py")}
IMPORT_TREES = {"exec_depends": "tactile_dock_ros", "test_depends": "test"}


def _top_level_imports(root: Path) -> set[str]:
    names = set()
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names.add(node.module.split(".")[0])
    return names - LOCAL - set(sys.stdlib_module_names)


def _used(kind: str) -> set[str]:
    """Keys that `kind` dependencies (exec_depends, test_depends, ...) of the package need."""
    tree = IMPORT_TREES.get(kind)
    keys = {ROSDEP_KEYS.get(n) for n in _top_level_imports(REPO_ROOT / tree)} if tree else set()
    for key, (use_kind, pattern, regex) in OTHER_USES.items():
        files = REPO_ROOT.glob(pattern)
        if use_kind == kind and any(re.search(regex, f.read_text()) for f in files):
            keys.add(key)
    return keys - {None}


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
    imported = _top_level_imports(REPO_ROOT / tree) - PIP_ONLY.keys()
    unknown = imported - ROSDEP_KEYS.keys()
    assert not unknown, f"add a rosdep key for {unknown} to ROSDEP_KEYS and package.xml"
    missing = {ROSDEP_KEYS[name] for name in imported} - declared
    assert not missing, f"package.xml lacks {kinds} {missing}"


@pytest.mark.parametrize("kind", ["buildtool_depends", "exec_depends", "test_depends"])
def test_declared_dependencies_are_used(package, kind):
    """A dependency nothing imports, builds with or launches is dead weight on every install."""
    unused = {d.name for d in getattr(package, kind)} - _used(kind)
    assert not unused, f"package.xml declares unused {kind} {unused}"


def test_every_key_is_a_rosdep_key(package):
    kinds = ("buildtool_depends", "build_depends", "exec_depends", "test_depends")
    deps = {d.name for kind in kinds for d in getattr(package, kind)}
    assert deps <= SYSTEM_KEYS | ROS_KEYS, f"not rosdep keys: {deps - SYSTEM_KEYS - ROS_KEYS}"
    assert set(ROSDEP_KEYS.values()) <= SYSTEM_KEYS | ROS_KEYS


def _pins(name: str) -> dict[str, str]:
    text = (REPO_ROOT / name).read_text()
    return {canonicalize_name(n): v for n, v in re.findall(r"^([\w.-]+)==(\S+)", text, re.M)}


def _imported_distributions(tree: str) -> set[str]:
    providers = metadata.packages_distributions()
    modules = _top_level_imports(REPO_ROOT / tree)
    return {canonicalize_name(d) for m in modules for d in providers.get(m, ())}


def test_pip_only_imports_are_exactly_requirements_pip():
    assert set(_pins("requirements-pip.txt")) == set(PIP_ONLY.values())
    imported = _top_level_imports(REPO_ROOT / "tactile_dock_ros") | _top_level_imports(
        REPO_ROOT / "test"
    )
    assert PIP_ONLY.keys() <= imported, "stale PIP_ONLY"


def _setup_args() -> dict:
    setup = next(
        node
        for node in ast.walk(ast.parse((REPO_ROOT / "setup.py").read_text()))
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "setup"
    )
    return {k.arg: ast.literal_eval(k.value) for k in setup.keywords}


def test_setup_py_requires_only_imported_distributions():
    args = _setup_args()
    extras = [r for reqs in args["extras_require"].values() for r in reqs]
    declared = {canonicalize_name(Requirement(r).name) for r in args["install_requires"] + extras}
    unused = declared - _imported_distributions("tactile_dock_ros")
    assert not unused, f"setup.py requires distributions nothing imports: {unused}"


def test_setup_py_installs_every_subpackage_but_the_nodes():
    """`pip install .` gives the ROS-free layers and the tools; the rclpy nodes need the ROS
    build (CMakeLists.txt installs the whole tree)."""
    root = REPO_ROOT / "tactile_dock_ros"
    subpackages = {
        ".".join(p.parent.relative_to(root).parts) for p in root.glob("**/__init__.py")
    } - {"", "nodes"}
    expected = {"tactile_dock_ros", *(f"tactile_dock_ros.{name}" for name in subpackages)}
    assert set(_setup_args()["packages"]) == expected
    assert {f"tactile_dock_ros.{layer}" for layer in ROS_FREE} <= expected


def test_ros_free_layers_load_without_ros():
    """core/, perception/ and execution/ import neither rclpy, nor a message package, nor the
    layers above them (nodes, tools), directly or through each other: every module is imported
    in a fresh interpreter and the modules it loaded are checked."""
    probe = (
        "import importlib, pkgutil, sys\n"
        f"for layer in {ROS_FREE!r}:\n"
        "    package = importlib.import_module('tactile_dock_ros.' + layer)\n"
        "    for info in pkgutil.iter_modules(package.__path__, package.__name__ + '.'):\n"
        "        importlib.import_module(info.name)\n"
        "print(' '.join(sys.modules))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", probe], cwd=REPO_ROOT, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    ros = {name for name, key in ROSDEP_KEYS.items() if not key.startswith("python3-")}
    above = ("tactile_dock_ros.msg", "tactile_dock_ros.nodes", "tactile_dock_ros.tools")
    loaded = run.stdout.split()
    assert "tactile_dock_ros.execution.guarded" in loaded
    assert [m for m in loaded if m.split(".")[0] in ros or m.startswith(above)] == []


def _imports(path: Path, package: str) -> set[str]:
    """Absolute names of the modules the file ``path`` of ``package`` imports."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            names.add(".".join(filter(None, [base, node.module])))
    return names


def test_nodes_never_import_the_tools():
    """Layers import downward only: tools -> nodes -> execution, perception -> core."""
    nodes = REPO_ROOT / "tactile_dock_ros" / "nodes"
    upward = {
        (path.name, module)
        for path in nodes.glob("*.py")
        for module in _imports(path, "tactile_dock_ros.nodes")
        if module.startswith("tactile_dock_ros.tools")
    }
    assert upward == set()


def test_jazzy_and_kilted_pin_the_same_non_ros_packages():
    """`make test ROS_DISTRO=jazzy` differs from the default only in its ROS wheels."""
    kilted, jazzy = _pins("requirements.txt"), _pins("requirements-jazzy.txt")
    non_ros = {n: v for n, v in kilted.items() if not n.startswith("ros-")}
    assert {n: v for n, v in jazzy.items() if not n.startswith("ros-")} == non_ros
    assert {"ros-jazzy-rclpy", "ros-rclpy", "pytest"} <= jazzy.keys()
    assert not any(n.startswith("ros-jazzy-") for n in kilted)


@pytest.mark.parametrize("distro", ["kilted", "jazzy"])
def test_make_builds_each_distro_in_its_own_venv(distro, tmp_path):
    """`make test ROS_DISTRO=jazzy`: its own venv, pins and message build (dry run)."""
    venv = tmp_path / "venv"
    run = subprocess.run(
        ["make", "-n", "setup", f"ROS_DISTRO={distro}", f"VENV={venv}"],
        cwd=REPO_ROOT, capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    requirements = {"kilted": "requirements.txt", "jazzy": "requirements-jazzy.txt"}[distro]
    assert f"{venv}/bin/python -m pip install" in run.stdout
    assert f"-r {requirements}" in run.stdout
    assert f"-B build/{distro}" in run.stdout


def _test_domain(worker: str | None, inherited: str) -> int:
    """The ROS_DOMAIN_ID a test process gets from conftest.py, as xdist worker ``worker``
    (None: a single pytest process) started with ``inherited`` in its environment."""
    env = {**os.environ, "ROS_DOMAIN_ID": inherited, "PYTHONPATH": str(REPO_ROOT / "test")}
    env.pop("PYTEST_XDIST_WORKER", None)
    if worker is not None:
        env["PYTEST_XDIST_WORKER"] = worker
    code = "import os, conftest; print(os.environ['ROS_DOMAIN_ID'])"
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return int(run.stdout)


def test_each_pytest_worker_runs_on_its_own_dds_domain():
    """`make test` (pytest -n): a worker takes the controller's random domain + 1 + its index,
    so the workers' nodes never discover each other; a single process draws its own."""
    assert [_test_domain(w, "150") for w in ("gw0", "gw1")] == [151, 152]
    alone = _test_domain(None, "7")  # a user's domain is replaced by a random test domain
    assert 100 <= alone <= 200


def test_make_refuses_a_distro_without_pypi_wheels():
    run = subprocess.run(
        ["make", "-n", "setup", "ROS_DISTRO=humble"], cwd=REPO_ROOT, capture_output=True, text=True
    )
    assert run.returncode != 0
    assert "ROS_DISTRO=humble" in run.stderr and "jazzy" in run.stderr


@pytest.mark.parametrize("name", ["requirements.txt", "requirements-jazzy.txt"])
def test_every_pin_is_needed(name):
    """Each pin is imported by the package or its tests, a tool in TOOLS, a ROS wheel, or a
    dependency of one of those (markers and extras evaluated): a pin only a removed package
    needed fails here. Runs in the venv built from that file."""
    pins = _pins(name)
    installed = {canonicalize_name(d.metadata["Name"]): d for d in metadata.distributions()}
    if any(n not in installed or installed[n].version != v for n, v in pins.items()):
        pytest.skip(f"this environment was not built from {name}")
    roots = _imported_distributions("tactile_dock_ros") | _imported_distributions("test")
    todo = [(n, "") for n in roots | TOOLS | {n for n in pins if n.startswith("ros-")}]
    needed = set()
    while todo:
        dist, extra = todo.pop()
        if (dist, extra) in needed or dist not in installed:
            continue
        needed.add((dist, extra))
        for req in map(Requirement, installed[dist].requires or ()):
            if req.marker is None or req.marker.evaluate({"extra": extra}):
                todo += [(canonicalize_name(req.name), e) for e in ("", *req.extras)]
    unused = set(pins) - {dist for dist, _ in needed}
    assert not unused, f"{name} pins what nothing needs: {sorted(unused)}"


@pytest.mark.skipif(
    not (shutil.which("rosdep") and os.environ.get("ROS_DISTRO")),
    reason="rosdep and a sourced ROS 2 (ROS_DISTRO) are needed; not on the PyPI-wheel machines",
)
def test_rosdep_resolves_every_key():
    run = subprocess.run(
        ["rosdep", "check", "--from-paths", str(REPO_ROOT), "--ignore-src"],
        capture_output=True,
        text=True,
    )
    if "rosdep init" in run.stderr or "rosdep update" in run.stderr:
        pytest.skip("rosdep database not initialized: " + run.stderr.strip())
    assert "Cannot locate rosdep definition" not in run.stdout + run.stderr, run.stderr


LEGACY_HOOK_PLUGIN = '''
def pytest_pycollect_makemodule(path, parent):
    """The py.path `path` argument, as launch_testing's collection hook declares it."""
'''


def test_pytest_loads_a_plugin_with_launch_testing_hook_signature(tmp_path):
    """launch_testing's pytest plugin (Humble; Jazzy before 3.4.12; Kilted before 3.8.9) declares
    pytest_pycollect_makemodule(path, parent). pytest 9 removed `path`, so its plugin registration
    fails and every pytest run aborts once launch_testing is installed (ros2/launch#979): the
    pinned pytest must still accept it."""
    (tmp_path / "legacy_hook_plugin.py").write_text(LEGACY_HOOK_PLUGIN)
    (tmp_path / "test_one.py").write_text("def test_one():\n    pass\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    env.pop("PYTEST_ADDOPTS", None)  # the selection of an outer run (make colcon-test)
    args = ["-p", "legacy_hook_plugin", "-p", "no:cacheprovider", "-W", "ignore", "test_one.py"]
    run = subprocess.run(
        [sys.executable, "-m", "pytest", *args],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "1 passed" in run.stdout


def test_ruff_passes_on_the_whole_tree():
    ruff = [sys.executable, "-m", "ruff"]
    check = subprocess.run([*ruff, "check", "."], cwd=REPO_ROOT, capture_output=True, text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    fmt = subprocess.run(
        [*ruff, "format", "--check", "."], cwd=REPO_ROOT, capture_output=True, text=True
    )
    assert fmt.returncode == 0, fmt.stdout + fmt.stderr
