"""The launch files: both profiles parse, executables exist, mock and robot sides agree."""

import os
from pathlib import Path

import pytest
import yaml
from conftest import REPO_ROOT
from node_helpers import LAUNCH_FILE, SHARE, launch_nodes

from tactile_dock_ros.tools import launch_xml

CORE = {"perception", "inference", "planner", "executor"}


def test_mock_profile_adds_mock_hardware_to_the_four_nodes():
    assert set(launch_nodes("mock")) == CORE | {"mock_hardware"}
    assert set(launch_nodes("robot")) == CORE


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_every_node_runs_an_installed_script_with_the_profile_config(profile):
    for node in launch_nodes(profile).values():
        script = REPO_ROOT / "scripts" / node.executable
        assert script.is_file() and os.access(script, os.X_OK), script
        assert f"tactile_dock_ros.nodes.{node.executable}" in script.read_text()
        assert node.parameter_files() == [REPO_ROOT / "config" / f"{profile}.yaml"]


def test_mock_hardware_serves_exactly_the_topics_the_executor_uses():
    nodes = launch_nodes("mock", arm_command_topic="/my_arm/twist")
    executor = dict(nodes["executor"].remappings)
    mock = dict(nodes["mock_hardware"].remappings)
    for topic in ("cmd_twist", "tool_pose", "wrench"):
        assert executor[topic] == mock[topic]
    assert executor["cmd_twist"] == "/my_arm/twist"
    assert dict(nodes["planner"].remappings)["tool_pose"] == executor["tool_pose"]


def test_launch_arguments_reach_the_node_parameters():
    nodes = launch_nodes("mock", seed="17", problem="notch")
    values = nodes["mock_hardware"].parameter_values()
    assert values["seed"] == "17" and values["problem"] == "notch"
    assert nodes["perception"].parameter_values()["problem"] == "notch"


def test_command_line_carries_name_params_and_remaps(tmp_path):
    argv = launch_nodes("mock", seed="5")["mock_hardware"].command(REPO_ROOT / "scripts", tmp_path)
    assert argv[argv.index("--ros-args") + 1 :][:2] == ["-r", "__node:=mock_hardware"]
    files = [argv[i + 1] for i, a in enumerate(argv) if a == "--params-file"]
    assert files[0] == str(REPO_ROOT / "config" / "mock.yaml")
    overrides = yaml.safe_load(Path(files[1]).read_text())["/mock_hardware"]["ros__parameters"]
    assert overrides["seed"] == 5 and overrides["terrain_file"] == ""  # YAML-typed, as launch
    assert "-r" in argv and "cmd_twist:=/arm/cmd_twist" in argv


def test_unknown_arguments_and_profiles_are_errors():
    with pytest.raises(ValueError, match="unknown launch arguments"):
        launch_xml.parse(LAUNCH_FILE, SHARE, {"profil": "mock"})
    with pytest.raises(FileNotFoundError):
        launch_xml.parse(LAUNCH_FILE, SHARE, {"profile": "simulation"})


def test_set_env_reaches_every_node_including_included_ones(tmp_path):
    nodes = launch_nodes("mock")
    assert {n.environment.get("OPENBLAS_NUM_THREADS") for n in nodes.values()} == {"1"}
    assert launch_nodes("mock", blas_threads="2")["mock_hardware"].environment == {
        "OPENBLAS_NUM_THREADS": "2"
    }
    late = tmp_path / "late.launch.xml"
    late.write_text(
        '<launch><node pkg="p" exec="a" name="a"/><set_env name="X" value="1"/>'
        '<node pkg="p" exec="b" name="b"/></launch>'
    )
    first, second = launch_xml.parse(late, SHARE)
    assert first.environment == {} and second.environment == {"X": "1"}
