"""Every node's parameters load from the config files; bad values stop the node with a reason."""

import importlib.util

import pytest
import yaml
from conftest import REPO_ROOT
from node_helpers import launch_nodes, node_from_launch

# Nodes whose core library may not be merged yet: skipped (with the reason) until it is.
CORE_OF = {"inference_node": "tactile_dock_ros.core.sampling",
           "planner_node": "tactile_dock_ros.core.planner"}  # fmt: skip


def _skip_without_core(executable: str) -> None:
    module = CORE_OF.get(executable)
    if module and importlib.util.find_spec(module) is None:
        pytest.skip(f"{module} is not in this tree yet")


def _cases():
    for profile in ("mock", "robot"):
        for name, spec in launch_nodes(profile).items():
            yield pytest.param(profile, name, spec, id=f"{profile}-{name}")


@pytest.mark.parametrize(("profile", "name", "spec"), list(_cases()))
def test_parameters_load_from_the_config_file(profile, name, spec, tmp_path):
    _skip_without_core(spec.executable)
    if spec.executable == "perception_node" and profile == "robot":
        if importlib.util.find_spec("tactile_dock_ros.perception.depth") is None:
            pytest.skip("prior_source: depth needs tactile_dock_ros.perception (not merged yet)")
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    own = config.get(name, {}).get("ros__parameters", {})
    shared = config.get("/**", {}).get("ros__parameters", {})
    with node_from_launch(spec, tmp_path) as (node, _):
        for key, value in own.items():
            assert node.has_parameter(key), f"{name}: config key {key} is not a parameter"
            assert node.get_parameter(key).value == pytest.approx(value), key
        for key, value in shared.items():
            if node.has_parameter(key):
                assert node.get_parameter(key).value == pytest.approx(value), key


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_shared_config_keys_are_used_by_some_node(profile):
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    declared = set()
    for module in ("executor_node", "mock_hardware_node", "perception_node"):
        params = importlib.import_module(f"tactile_dock_ros.nodes.{module}").PARAMS
        declared |= {p.name for p in params}
    assert set(config["/**"]["ros__parameters"]) <= declared


@pytest.mark.parametrize(
    ("name", "override", "match"),
    [
        ("executor", "max_speed:=5.0", "max_speed"),
        ("executor", "workspace_min:=[0.0, 0.0, 0.0]", "workspace_min"),
        ("executor", "workspace_min:=[2.0, 2.0]", "workspace_min must be below"),
        ("mock_hardware", "rate_hz:=0.0", "rate_hz"),
        ("mock_hardware", "stiffness:=500", "stiffness"),  # an integer where a float is due
        ("perception", "capture:=sometimes", "capture"),
    ],
)
def test_invalid_parameter_values_stop_the_node(name, override, match, tmp_path):
    spec = launch_nodes("mock")[name]
    with (
        pytest.raises(ValueError, match=match),
        node_from_launch(spec, tmp_path, ["-p", f"{name}:{override}"]),
    ):
        pass


def test_an_unknown_problem_stops_mock_hardware(tmp_path):
    spec = launch_nodes("mock", problem="everest")["mock_hardware"]
    with pytest.raises(ValueError, match="problem"), node_from_launch(spec, tmp_path):
        pass
