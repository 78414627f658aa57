"""executor + mock_hardware (+ perception on the mock camera) as separate processes over DDS.

The processes are started from the mock launch file; the test plays the planner's part.
"""

import numpy as np
import pytest
import yaml
from conftest import REPO_ROOT
from geometry_msgs.msg import TwistStamped
from ros_helpers import ros_node, spin_until
from tactile_dock_ros.msg import DockingPlan, ExecutionReport, ShapeDistribution

from tactile_dock_ros.core.history import Status
from tactile_dock_ros.execution.types import PlanCommand
from tactile_dock_ros.nodes import convert, qos
from tactile_dock_ros.perception.learned_prior import TerrainLibrary
from tactile_dock_ros.tools import bringup

pytestmark = pytest.mark.dds

FLOOR = {"vertices": [[0.6, 0.0], [-0.6, 0.0]], "start": [0.0, 0.3], "friction": 0.5}


def _plan(plan_id, waypoints, speed=0.2):
    command = PlanCommand(
        plan_id, True, np.array(waypoints, float), np.array([0.0, -1.0]), 3.0, speed, False,
        0.5, 0.5, 0, "test",
    )  # fmt: skip
    return convert.plan_to_msg(command, convert.Header(frame_id="dock_plane"))


@pytest.fixture(scope="module")
def floor_bringup(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("floor")
    terrain = tmp / "floor.yaml"
    terrain.write_text(yaml.safe_dump(FLOOR))
    # no camera: its floor images would reach the perception test's node, which runs while
    # this module-scoped fixture does, on the same DDS domain
    arguments = {"profile": "mock", "terrain_file": str(terrain), "perception_config": ""}
    with bringup.running(arguments, tmp, only={"executor", "mock_hardware"}) as processes:
        yield processes


def test_executor_docks_on_the_mock_floor_and_respects_its_limits(floor_bringup):
    processes = floor_bringup
    executor_params = yaml.safe_load((bringup.PACKAGE_ROOT / "config/mock.yaml").read_text())
    limits = executor_params["executor"]["ros__parameters"]
    reports, speeds = [], []
    with ros_node("test_planner") as (node, executor):
        plan_pub = node.create_publisher(DockingPlan, "plan", qos.EVENTS)
        # Latched reports: one published before this reader matched still arrives.
        node.create_subscription(ExecutionReport, "execution_report", reports.append, qos.REPORTS)
        node.create_subscription(
            TwistStamped,
            "/arm/cmd_twist",
            lambda m: speeds.append(
                np.hypot(np.hypot(m.twist.linear.x, m.twist.linear.y), m.twist.linear.z)
            ),
            qos.COMMAND,
        )
        matched = spin_until(
            executor,
            lambda: (
                plan_pub.get_subscription_count() > 0
                and node.count_publishers("execution_report") > 0
                and node.count_publishers("/arm/cmd_twist") > 0
            ),
            timeout_s=30.0,
        )
        assert matched, [p.poll() for p in processes.values()]
        # Like the planner, resend each plan until its report comes: the executor ignores
        # copies it has seen, and a copy sent before its reader matched the writer is lost.
        for plan, speed in ((1, 0.9), (2, 0.2)):  # plan 1 is too fast
            message = _plan(plan, [[0.0, 0.3], [0.0, 0.1], [0.0, -0.1]], speed=speed)
            resend = node.create_timer(0.5, lambda m=message: plan_pub.publish(m))
            plan_pub.publish(message)
            assert spin_until(executor, lambda n=plan: len(reports) == n, timeout_s=30.0)
            node.destroy_timer(resend)
    refused, docked = (convert.report_from_msg(r) for r in reports)
    assert refused.outcome == ExecutionReport.ABORTED and "speed" in refused.detail
    assert len(refused.history) == 0
    assert docked.outcome == ExecutionReport.DOCKED, docked.detail
    assert docked.history.status[-1] == Status.STICK
    assert abs(docked.stop_point[1]) < 0.005  # resting on the floor
    assert speeds and max(speeds) <= limits["max_speed"] + 1e-9


@pytest.mark.parametrize("prior_source", ["depth", "generic"])
def test_perception_builds_a_prior_from_the_mock_camera(tmp_path, prior_source):
    arguments = {"profile": "mock", "problem": "notch", "seed": "2", "prior_source": prior_source}
    priors = []
    with (
        bringup.running(arguments, tmp_path, only={"perception", "mock_hardware"}),
        ros_node("prior_listener") as (node, executor),
    ):
        node.create_subscription(ShapeDistribution, "terrain_prior", priors.append, qos.LATCHED)
        spin_until(executor, lambda: priors, timeout_s=60.0)
    assert priors, (tmp_path / "perception.log").read_text()[-2000:]
    prior = convert.shape_from_msg(priors[0])
    assert prior.n_vertices >= 10 and prior.n_basis > 0
    learned = TerrainLibrary.load(REPO_ROOT / "config" / "terrain_classes.npz").get("notch")
    log = (tmp_path / "perception.log").read_text()
    if prior_source == "depth":  # the notch class's vertices, conditioned on the image
        assert prior.n_vertices == learned.n_vertices and "learned prior: class notch" in log
    else:
        assert prior.n_vertices != learned.n_vertices and "learned" not in log
