"""docs/nodes.md's node reference is what ``tools.describe`` generates from the nodes."""

import os

import pytest
from conftest import REPO_ROOT

from tactile_dock_ros.nodes import executor_node, qos
from tactile_dock_ros.nodes.params import Param
from tactile_dock_ros.tools import describe

pytestmark = pytest.mark.dds  # builds every node in-process (rclpy contexts, DDS participants)

DOC = REPO_ROOT / "docs" / "nodes.md"


@pytest.fixture(scope="module")
def generated() -> str:
    return describe.generate()


def _node_section(text: str, name: str) -> str:
    start = text.index(f"### `{name}` (")
    end = text.find("\n### ", start + 1)
    return text[start : end if end > 0 else len(text)]


def test_docs_nodes_md_has_the_generated_reference(generated):
    current, diff = describe.check(DOC, generated)
    assert current, f"stale: python -m tactile_dock_ros.tools.describe --output {DOC}\n{diff}"


def test_reference_lists_parameters_with_unit_and_range_and_the_created_topics(generated):
    executor = _node_section(generated, "executor")
    (max_speed,) = [p for p in executor_node.PARAMS if p.name == "max_speed"]
    assert max_speed.unit == "m/s"
    row = f"| `max_speed` | double | `{max_speed.default!r}` | [{max_speed.low!r}, "
    assert row + f"{max_speed.high!r}] | m/s | {max_speed.description} |" in executor
    planner = _node_section(generated, "planner")
    publications = planner[planner.index("Publications:") : planner.index("Services:")]
    plan = "| `/plan` | `tactile_dock_ros/msg/DockingPlan` | reliable | volatile |"
    assert f"{plan} {qos.EVENTS.depth} |" in publications
    assert "| `/start_episode` | `std_srvs/srv/Trigger` |" in planner
    assert "Action servers:\n\n| action | type |\n" in planner
    assert "| `/dock` | `tactile_dock_ros/action/Dock` |" in planner
    # what rclpy creates on every node is not the suite's
    for builtin in ("/parameter_events", "describe_parameters", "get_type_description"):
        assert builtin not in generated
    assert "`use_sim_time`" not in generated


def test_check_fails_with_a_diff_when_a_parameter_is_added(monkeypatch, capsys):
    extra = Param("extra_gain", 2.0, "a parameter the reference does not list", "1/s", 0.0, 10.0)
    monkeypatch.setattr(executor_node, "PARAMS", [*executor_node.PARAMS, extra])
    for name in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):  # main() picks a domain
        monkeypatch.setenv(name, os.environ[name])
    assert describe.main(["--check", str(DOC)]) == 1
    out = capsys.readouterr()
    assert "+| `extra_gain` | double | `2.0` | [0.0, 10.0] | 1/s |" in out.out
    assert "is stale" in out.err


def test_output_replaces_only_the_generated_section(generated, tmp_path):
    path = tmp_path / "nodes.md"
    path.write_text(f"# Title\n\nprose\n\n{describe.BEGIN}\nold\n{describe.END}\n\nmore prose\n")
    path.write_text(describe.replace_section(path.read_text(), generated))
    text = path.read_text()
    assert text.startswith("# Title\n\nprose\n\n") and text.endswith("\n\nmore prose\n")
    assert describe.check(path, generated)[0]
    assert "old" not in describe.section(text).splitlines()
