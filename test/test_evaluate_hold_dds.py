"""/evaluate_hold over DDS: three holds captured from the mock camera, each answered with
exactly what core.planner.plan gives on the same prior and prior draws."""

import re
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Point, PoseStamped
from ros_helpers import ros_node, spin_until
from std_srvs.srv import Trigger
from tactile_dock_ros.msg import HoldEvaluation, ShapeDistribution
from tactile_dock_ros.srv import EvaluateHold

from tactile_dock_ros.core import planner, sampling
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.history import History
from tactile_dock_ros.nodes import convert, perception_node, planner_node, qos
from tactile_dock_ros.tools import bringup

pytestmark = pytest.mark.dds

TOOL = (0.02, 0.25)  # plane frame, metres: above the notch, in the open


def _settings():
    """Perception's evaluation settings under the mock profile: its parameter defaults, the
    shared and its own config keys (the planner's settings are declared from the planner's
    table with its defaults, test_holds)."""
    config = yaml.safe_load((bringup.PACKAGE_ROOT / "config" / "mock.yaml").read_text())
    values = {p.name: p.default for p in perception_node.PARAMS}
    for section in ("/**", "perception"):
        values.update(config[section]["ros__parameters"])
    return SimpleNamespace(**values)


def _call(node, executor, client, request):
    future = client.call_async(request)
    assert spin_until(executor, future.done, 60.0), "no answer"
    return future.result()


def _expected(prior_msg, tool, p):
    """The first cycle's plan computed here: the prior's draws, then core.planner.plan."""
    shape = convert.shape_from_msg(prior_msg)
    rng = np.random.default_rng(p.evaluate_seed)
    draws = sampling.sample_posterior(shape, History(), p.evaluate_samples, rng).vertices
    config = planner_node.planner_config(p)
    return planner.plan(draws, shape, EpisodeState(tool=tool), config)


def _check(result: HoldEvaluation, prior_msg, plan) -> None:
    assert result.found and result.header.stamp == prior_msg.header.stamp
    assert result.header.frame_id == prior_msg.header.frame_id
    assert result.decision == (HoldEvaluation.DOCK if plan.decision == "dock" else 1)
    assert result.reason == plan.reason and result.target_edge == plan.target_edge
    # computed in another process: equal up to rounding (its BLAS may sum in another order)
    close = {"rel": 1e-9, "abs": 1e-12}
    assert result.path_docking_probability == pytest.approx(plan.p_dock, **close)
    if plan.decision == "dock":
        j = np.flatnonzero(plan.candidates.edges == plan.target_edge)[0]
        assert [result.site.x, result.site.y] == pytest.approx(plan.target_point.tolist(), **close)
        assert result.site_docking_probability == pytest.approx(plan.candidates.p_dock[j], **close)
    assert result.compute_time > 0


def test_three_captured_holds_are_evaluated_as_the_planner_plans(tmp_path):
    p = _settings()
    # the generic prior: each capture draws its occlusion anew, so the three holds differ (the
    # class library's posterior of the mock's still image is the same at every capture)
    arguments = {"profile": "mock", "problem": "notch", "seed": "2", "prior_source": "generic"}
    priors, poses = [], []
    with (
        bringup.running(arguments, tmp_path, only={"perception", "mock_hardware"}) as processes,
        ros_node("hold_caller") as (node, executor),
    ):
        node.create_subscription(ShapeDistribution, "terrain_prior", priors.append, qos.LATCHED)
        node.create_subscription(PoseStamped, "/arm/tool_pose", poses.append, qos.SENSOR)
        capture = node.create_client(Trigger, "/perception/capture")
        evaluate = node.create_client(EvaluateHold, "/evaluate_hold")
        ready = spin_until(
            executor,
            lambda: priors and poses and capture.service_is_ready() and evaluate.service_is_ready(),
            60.0,
        )
        assert ready, (tmp_path / "perception.log").read_text()[-2000:]
        for hold_id in (2, 3):  # hold 1 is the first frame's
            answer = _call(node, executor, capture, Trigger.Request())
            assert answer.success and re.match(rf"hold {hold_id}: ", answer.message)
            assert spin_until(executor, lambda n=hold_id: len(priors) == n, 60.0)
        tool = Point(x=TOOL[0], y=TOOL[1])
        request = EvaluateHold.Request(use_tool_position=True, tool_position=tool)
        every = _call(node, executor, evaluate, request)
        bad = EvaluateHold.Request(hold_ids=[99, 2], use_tool_position=True, tool_position=tool)
        mixed = _call(node, executor, evaluate, bad)
        again = _call(node, executor, evaluate, request)
        from_pose = _call(node, executor, evaluate, EvaluateHold.Request(hold_ids=[3]))
        nan = Point(x=float("nan"), y=0.0)
        refused = _call(
            node,
            executor,
            evaluate,
            EvaluateHold.Request(use_tool_position=True, tool_position=nan),
        )
        assert all(process.poll() is None for process in processes.values())
    assert every.success and [h.hold_id for h in every.holds] == [1, 2, 3]
    # three different priors: a mix-up would show
    means = [tuple(m.mean) for m in priors]
    assert len(set(means)) == 3
    for result, prior_msg in zip(every.holds, priors, strict=True):
        _check(result, prior_msg, _expected(prior_msg, np.array(TOOL), p))
    # an unknown id is answered, not raised; the known one and a repeat are unchanged
    assert mixed.success and [h.hold_id for h in mixed.holds] == [99, 2]
    unknown, known = mixed.holds
    assert not unknown.found and "no hold 99" in unknown.reason and "[1, 2, 3]" in unknown.reason
    _check(known, priors[1], _expected(priors[1], np.array(TOOL), p))
    assert _untimed(again.holds) == _untimed(every.holds)
    # without an override: from the latest tool pose
    assert from_pose.success and [h.hold_id for h in from_pose.holds] == [3]
    assert from_pose.holds[0].found and from_pose.holds[0].reason
    assert not refused.success and "NaN or inf" in refused.message and not refused.holds


def _untimed(results: list[HoldEvaluation]) -> list[HoldEvaluation]:
    """``results`` without their compute time, the one field a repeat may change."""
    for result in results:
        result.compute_time = 0.0
    return results
