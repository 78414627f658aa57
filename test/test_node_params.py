"""Every node's parameters load from the config files; bad values stop the node with a reason."""

import importlib

import pytest
import yaml
from conftest import REPO_ROOT
from node_helpers import launch_nodes, node_from_launch

from tactile_dock_ros.core import planner


def _cases():
    for profile in ("mock", "robot"):
        for name, spec in launch_nodes(profile).items():
            yield pytest.param(profile, name, spec, id=f"{profile}-{name}")


@pytest.mark.parametrize(("profile", "name", "spec"), list(_cases()))
def test_parameters_load_from_the_config_file(profile, name, spec, tmp_path):
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
        ("executor", "workspace_max:=[.inf, 1.0]", "workspace_max: .* is not finite"),
        ("executor", "wrench_frame:=sensor", "wrench_frame"),
        ("mock_hardware", "rate_hz:=0.0", "rate_hz"),
        ("mock_hardware", "stiffness:=500", "stiffness"),  # an integer where a float is due
        ("perception", "capture:=sometimes", "capture"),
        ("inference", "method:=mh", "method: 'mh' is not one of"),  # a benchmark baseline only
        ("inference", "method:=gibbs", "method: 'gibbs' is not one of"),  # biased on depth priors
        ("planner", "load_direction:=[0.0, -0.5]", "load_direction must be a unit vector"),
        ("inference", "load_direction:=[0.6, 0.6]", "load_direction must be a unit vector"),
        # list parameters: each value within its range
        ("planner", "load_direction:=[0.0, -2.0]", r"load_direction: \[0.0, -2.0\] is below -1"),
        ("executor", "workspace_max:=[500.0, 1.0]", "workspace_max: .* is above 100"),
        ("mock_hardware", "calibration_error:=[0.0, 0.0, 0.0, 0.0, 0.0, 2.0]", "above 0.5"),
        ("mock_hardware", "force_bias:=[1000.0, 0.0, 0.0]", "force_bias: .* is above 100"),
        ("perception", "plane_origin:=[0.0, 1000.0, 0.0]", "plane_origin: .* is above 100"),
    ],
)
def test_invalid_parameter_values_stop_the_node(name, override, match, tmp_path):
    spec = launch_nodes("mock")[name]
    with (
        pytest.raises(ValueError, match=match),
        node_from_launch(spec, tmp_path, ["-p", f"{name}:{override}"]),
    ):
        pass


@pytest.mark.parametrize("check", ["on", "off"])
def test_a_sample_request_must_time_out_before_the_stage(check, tmp_path):
    """With the give-up check on, ``sample_request_timeout`` at or above ``stage_timeout`` (60 s
    in the mock profile) stops the planner; off, the timeout is unused and not checked."""
    spec = launch_nodes("mock")["planner"]
    args = ["-p", "planner:sample_request_timeout:=60.0", "-p",
            f"planner:give_up_samples:={400 if check == 'on' else 0}"]  # fmt: skip
    if check == "off":
        with node_from_launch(spec, tmp_path, args) as (node, _):
            assert node.p.sample_request_timeout == node.p.stage_timeout == 60.0
        return
    with (
        pytest.raises(ValueError, match=r"sample_request_timeout .* must be below stage_timeout"),
        node_from_launch(spec, tmp_path, args),
    ):
        pass


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_the_planner_plans_with_its_parameters(profile, tmp_path):
    from tactile_dock_ros.core.episode import PlannerConfig

    slide = ["-p", "planner:max_slide:=0.45"]  # a team's longer slides (not the profiles' 0.3 m)
    with node_from_launch(launch_nodes(profile)["planner"], tmp_path, slide) as (node, _):
        names = ("load_direction", "contact_resolution", "give_up_threshold", "compliant")
        names += ("max_slide",)
        value = {name: node.get_parameter(name).value for name in names}
        box = [node.get_parameter(f"workspace_{end}").value for end in ("min", "max")]
        config = node.config
    expected = PlannerConfig(
        tuple(value["load_direction"]),
        value["contact_resolution"],
        value["give_up_threshold"],
        compliant=value["compliant"],
        workspace=tuple(map(tuple, box)),
        max_slide=value["max_slide"],
    )
    assert config == expected and config.max_slide == 0.45


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_the_planner_plans_in_the_executors_workspace_box(profile):
    """A path the executor would refuse as outside its box is never planned: the profiles give
    the planner (and perception, for /evaluate_hold) the executor's box."""
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    for end in ("workspace_min", "workspace_max"):
        box = config["executor"]["ros__parameters"][end]
        assert config["planner"]["ros__parameters"][end] == box, end
        assert config["perception"]["ros__parameters"][end] == box, end


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_inference_conditions_slides_on_the_planners_load(profile):
    """Inference keeps the samples on which the recorded slides could have happened under the
    load (``core.episode_posterior``); the profiles give it the planner's load direction."""
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    load = config["planner"]["ros__parameters"]["load_direction"]
    assert config["inference"]["ros__parameters"]["load_direction"] == load


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_inference_draws_what_the_planners_give_up_needs(profile):
    """With no sample holding, inference draws on to ``give_up_draws``: the profiles give it the
    count the planner's threshold asks for (``planner.give_up_draws``)."""
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    threshold = config["planner"]["ros__parameters"]["give_up_threshold"]
    draws = config["inference"]["ros__parameters"]["give_up_draws"]
    assert (
        draws
        == planner.give_up_draws(threshold)
        > config["inference"]["ros__parameters"]["num_samples"]
    )


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_the_planner_knows_how_far_the_executor_may_slide(profile):
    """A slide the executor reports by its first contact only leaves the tool up to its
    ``max_slide`` from its moves; the planner steps back that far (``planner.retrace``), so
    the profiles give planner and perception the executor's value."""
    config = yaml.safe_load((REPO_ROOT / "config" / f"{profile}.yaml").read_text())
    slide = config["executor"]["ros__parameters"]["max_slide"]
    assert config["planner"]["ros__parameters"]["max_slide"] == slide
    assert config["perception"]["ros__parameters"]["max_slide"] == slide


def test_an_unknown_problem_stops_mock_hardware(tmp_path):
    spec = launch_nodes("mock", problem="everest")["mock_hardware"]
    with pytest.raises(ValueError, match="problem"), node_from_launch(spec, tmp_path):
        pass


def test_parameters_are_read_only_at_run_time(tmp_path):
    """The nodes read parameters once: a run-time change is refused, not silently ignored."""
    from rclpy.parameter import Parameter

    with node_from_launch(launch_nodes("mock")["executor"], tmp_path) as (node, _):
        result = node.set_parameters([Parameter("max_force", value=5.0)])[0]
        assert not result.successful and node.get_parameter("max_force").value == 40.0


def test_executor_defaults_are_the_guarded_settings_defaults():
    """One source: a node started without a config file executes like guarded.Settings()."""
    from dataclasses import fields

    from tactile_dock_ros.execution.guarded import Settings
    from tactile_dock_ros.nodes.executor_node import PARAMS

    node_defaults = {p.name: p.default for p in PARAMS}
    shared = [f.name for f in fields(Settings) if f.name in node_defaults]
    assert "slip_tolerance" in shared and len(shared) >= 9
    assert {n: node_defaults[n] for n in shared} == {n: getattr(Settings(), n) for n in shared}


def test_every_numeric_parameter_has_a_range_and_ros_describes_it():
    """Every number, or list of numbers, of every node's table has both bounds; ``ros2 param
    describe`` shows a scalar's as its range and a list's in the description."""
    modules = ("executor", "inference", "mock_hardware", "perception", "planner")
    for module in (f"{name}_node" for name in modules):
        for param in importlib.import_module(f"tactile_dock_ros.nodes.{module}").PARAMS:
            values = param.default if isinstance(param.default, list) else [param.default]
            numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
            if not numeric or not values:
                continue
            assert param.low is not None and param.high is not None, (module, param.name)
            text = param.descriptor().description
            if isinstance(param.default, list):
                assert f"(each in [{param.low:g}, {param.high:g}])" in text, (module, param.name)
                with pytest.raises(ValueError, match=param.name):
                    param.check([param.high + 1.0] * len(values))
