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
