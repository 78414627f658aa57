"""ShapeSamples that cannot come from the planner's prior (another vertex count, absurd
coordinates) are dropped over DDS and change nothing: a running episode goes on and plans on
the next valid samples (planner in-process, ``node_with_driver``)."""

import numpy as np
import pytest
from node_helpers import launch_nodes, node_with_driver, planner_episode, pose_msg
from ros_helpers import spin_until
from tactile_dock_ros.msg import EpisodeStatus, ShapeDistribution, ShapeSamples

from tactile_dock_ros.core import problems
from tactile_dock_ros.nodes import convert, qos

pytestmark = pytest.mark.dds


def test_samples_that_do_not_fit_the_prior_are_dropped_and_the_episode_goes_on(tmp_path):
    with planner_episode(tmp_path) as ep:
        node, executor, shape, stamp, samples = ep.node, ep.executor, ep.shape, ep.stamp, ep.samples
        statuses, plans = ep.statuses, ep.plans
        assert spin_until(executor, lambda: ep.pose.publish(pose_msg(0.0, 0.6, 0.45)) or (
            node.episode_state.tool is not None), 10.0)  # fmt: skip

        # Right after the new history: 3 vertices against the prior's, then the prior mean
        # times 1e150 (finite, within no bound of the prior).
        drawn = shape.vertices(np.random.default_rng(0).standard_normal((20, shape.n_basis)))
        few = convert.samples_to_msg(drawn[:, :3], stamp, "hmc", 5.0, 0)
        huge = convert.samples_to_msg(drawn * 1e150, stamp, "hmc", 5.0, 0)
        for dropped, bad in enumerate((few, huge), start=1):
            samples.publish(bad)
            assert spin_until(
                executor, lambda n=dropped: node.malformed.dropped["/shape_samples"] == n, 10.0
            ), bad.num_vertices
            assert node.samples is None and node.samples_ahead is None  # nothing kept
            assert node.state == "RUNNING" and not plans and not node.cycles
        assert statuses[-1].state == EpisodeStatus.RUNNING

        # The valid samples that follow are planned on (DOCK or GIVE_UP: the draw decides).
        good = convert.samples_to_msg(drawn, stamp, "hmc", 5.0, 0)
        samples.publish(good)
        assert spin_until(executor, lambda: bool(plans), 60.0)
        assert node.samples[0].num_vertices == shape.n_vertices
        assert len(node.cycles) == 1
    assert statuses[-1].state in (EpisodeStatus.RUNNING, EpisodeStatus.GAVE_UP), statuses[-1]
    assert "planner failed" not in statuses[-1].detail


def test_samples_before_the_prior_are_checked_when_it_comes(tmp_path):
    spec = launch_nodes("mock")["planner"]
    with node_with_driver(spec, tmp_path) as (node, driver, executor):
        prior = driver.create_publisher(ShapeDistribution, "terrain_prior", qos.LATCHED)
        samples = driver.create_publisher(ShapeSamples, "shape_samples", qos.LATCHED)
        publishers = (prior, samples)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in publishers), 10)
        shape = problems.get("sloper").prior
        drawn = shape.vertices(np.random.default_rng(1).standard_normal((5, shape.n_basis)))
        samples.publish(convert.samples_to_msg(drawn[:, :3], convert.Header(), "hmc", 5.0, 0))
        assert spin_until(executor, lambda: node.samples is not None, 10.0)  # kept unchecked
        prior.publish(convert.shape_to_msg(shape, convert.Header()))
        assert spin_until(executor, lambda: node.prior is not None, 10.0)
        assert node.samples is None  # they do not fit the prior: dropped before any use


@pytest.mark.parametrize("case", ["answered", "unanswered", "off"])
def test_a_give_up_after_a_contact_on_few_samples_asks_inference_for_more(
    tmp_path, monkeypatch, case
):
    """``give_up_samples`` 400: a give-up on 20 samples of a 1-row history is not published;
    a SampleRequest for 400 samples of that history, with the episode's id and nonce, is, and
    the give-up stands only when the plan on the answer (or, after ``sample_request_timeout``
    without one, on the samples at hand) gives up again. 0: the first give-up is published."""
    from tactile_dock_ros.msg import SampleRequest

    from tactile_dock_ros.core.episode import EpisodeState
    from tactile_dock_ros.core.history import History
    from tactile_dock_ros.core.planner import Plan
    from tactile_dock_ros.nodes import planner_node

    planned = []

    def gives_up(vertices, prior, state, config):
        planned.append((len(vertices), len(state.history)))
        return Plan("give_up", np.zeros((0, 2)), 0.0, 0.0, -1, "test", np.full(2, np.nan))

    monkeypatch.setattr(planner_node, "plan_docking", gives_up)
    wanted = 0 if case == "off" else 400
    args = ["-p", f"planner:give_up_samples:={wanted}", "-p",
            f"planner:sample_request_timeout:={0.5 if case == 'unanswered' else 30.0}"]  # fmt: skip
    with planner_episode(tmp_path, args) as ep:
        node, executor, shape, stamp = ep.node, ep.executor, ep.shape, ep.stamp
        requests = []
        ep.driver.create_subscription(SampleRequest, "sample_request", requests.append, qos.EVENTS)
        assert spin_until(executor, lambda: ep.pose.publish(pose_msg(0.0, 0.6, 0.45)) or (
            node.episode_state.tool is not None and node.request_pub.get_subscription_count()
        ), 10.0)  # fmt: skip
        row = History(np.array([[0.0, 0.5]]), np.array([[0.0, 0.3]]), np.array([0]))
        ep.history.publish(convert.history_to_msg(EpisodeState(row), stamp))
        assert spin_until(executor, lambda: len(node.episode_state.history) == 1, 10.0)
        drawn = shape.vertices(np.random.default_rng(0).standard_normal((400, shape.n_basis)))
        ep.samples.publish(convert.samples_to_msg(drawn[:20], stamp, "hmc", 5.0, 1))
        if case == "off":
            assert spin_until(executor, lambda: bool(ep.plans), 10.0)
            assert planned == [(20, 1)] and not requests and node.state == "GAVE_UP"
            return
        assert spin_until(executor, lambda: bool(requests), 10.0)
        request = convert.sample_request_from_msg(requests[-1])
        assert request == {"episode": node.episode, "nonce": node.nonce, "hold_id": 0,
                           "history_length": 1, "num_samples": 400}  # fmt: skip
        assert not ep.plans and node.state == "RUNNING" and planned == [(20, 1)]
        if case == "answered":  # a resample of the history is not the answer; 400 samples are
            again = convert.samples_to_msg(drawn[20:40], stamp, "hmc", 5.0, 1)
            ep.samples.publish(again)
            assert spin_until(executor, lambda: node.samples[0] == again, 10.0)
            assert not ep.plans and node.state == "RUNNING" and len(planned) == 1
            ep.samples.publish(convert.samples_to_msg(drawn, stamp, "hmc", 5.0, 1))
        assert spin_until(executor, lambda: bool(ep.plans), 10.0)
        assert node.state == "GAVE_UP" and len(requests) == 1
        assert planned == [(20, 1), (400 if case == "answered" else 20, 1)]
        assert ep.statuses[-1].state == EpisodeStatus.GAVE_UP
