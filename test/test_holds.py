"""Captured holds (core.holds): the bounded store and the first-look evaluation."""

import numpy as np
import pytest
from node_helpers import launch_nodes, node_from_launch

from tactile_dock_ros.core import holds, planner, problems, sampling
from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.history import History

SLOPER = problems.get("sloper")
CONFIG = PlannerConfig(SLOPER.load, SLOPER.contact_resolution, 1e-3, compliant=False)


def test_store_is_bounded_drops_the_oldest_and_numbers_holds_uniquely():
    store = holds.HoldStore(3)
    assert store.next_id == 1 and len(store) == 0 and store.get(1) is None
    dropped = []
    for k in range(7):
        assert store.next_id == k + 1
        hold, gone = store.add(1000 + k, SLOPER.prior)
        assert (hold.hold_id, hold.stamp, hold.prior) == (k + 1, 1000 + k, SLOPER.prior)
        dropped.append(None if gone is None else gone.hold_id)
        assert len(store) == min(k + 1, 3)
    assert dropped == [None, None, None, 1, 2, 3, 4]
    assert store.ids() == [5, 6, 7] and store.get(4) is None and store.get(7).stamp == 1006


def test_received_priors_keep_perceptions_ids_and_resolve_a_goals_hold():
    received = holds.ReceivedPriors(2)
    assert received.resolve(0) is None
    for hold_id in (1, 2, 3):
        notes = received.receive(
            hold_id, hold_id, problems.get(problems.names()[hold_id - 1]).prior
        )
    assert notes == ["hold 1 dropped: 2 are kept"] and received.holds.ids() == [2, 3]
    assert received.resolve(0).hold_id == 3 and received.resolve(1) is None
    received.receive(3, 9, SLOPER.prior)  # the latched latest delivered again: replaced
    assert received.holds.ids() == [2, 3] and received.resolve(3).stamp == 9
    notes = received.receive(1, 10, SLOPER.prior)  # perception restarted its numbering
    assert "restarted" in notes[0] and received.holds.ids() == [1]
    received.receive(0, 11, SLOPER.prior)  # no captured hold: only the latest
    assert received.resolve(0).hold_id == 0 and received.holds.ids() == [1]


@pytest.mark.parametrize("capacity", [0, -1, 2.5, True])
def test_store_capacity_must_be_a_positive_integer(capacity):
    with pytest.raises(ValueError, match="capacity"):
        holds.HoldStore(capacity)


@pytest.mark.parametrize(
    ("stamp", "prior", "match"),
    [
        (0, "sloper", "GaussianShape"),
        (1.5, SLOPER.prior, "nanoseconds"),
        (True, SLOPER.prior, "nanoseconds"),
    ],
)
def test_store_refuses_bad_holds_and_stores_nothing(stamp, prior, match):
    store = holds.HoldStore(2)
    store.add(1, SLOPER.prior)
    with pytest.raises(ValueError, match=match):
        store.add(stamp, prior)
    assert store.ids() == [1] and store.next_id == 2


@pytest.mark.parametrize("name", problems.names())
def test_evaluation_is_the_first_cycles_plan_on_prior_draws(name):
    problem = problems.get(name)
    config = PlannerConfig(problem.load, problem.contact_resolution, 1e-3, compliant=True)
    result = holds.evaluate_hold(problem.prior, problem.start, config, 40, seed=5)
    again = holds.evaluate_hold(problem.prior, problem.start, config, 40, seed=5)
    # the inference node's first cycle: sample_posterior on an empty history = prior draws
    draws = sampling.sample_posterior(problem.prior, History(), 40, np.random.default_rng(5))
    z = np.random.default_rng(5).standard_normal((40, problem.prior.n_basis))
    assert np.array_equal(draws.vertices, problem.prior.vertices(z))
    plan = planner.plan(draws.vertices, problem.prior, EpisodeState(tool=problem.start), config)
    for r in (result, again):
        assert r.decision == plan.decision and r.reason == plan.reason
        assert r.path_p_dock == plan.p_dock and r.target_edge == plan.target_edge
        if plan.decision == "dock":
            j = np.flatnonzero(plan.candidates.edges == plan.target_edge)[0]
            assert np.array_equal(r.site, plan.target_point)
            assert r.site_p_dock == plan.candidates.p_dock[j] >= r.path_p_dock
        assert r.seconds > 0


def test_a_give_up_names_the_best_candidate_site():
    config = PlannerConfig(SLOPER.load, SLOPER.contact_resolution, 0.999)
    result = holds.evaluate_hold(SLOPER.prior, SLOPER.start, config, 30, seed=1)
    draws = sampling.sample_posterior(SLOPER.prior, History(), 30, np.random.default_rng(1))
    plan = planner.plan(draws.vertices, SLOPER.prior, EpisodeState(tool=SLOPER.start), config)
    assert result.decision == plan.decision == "give_up" and result.path_p_dock == 0.0
    best = int(np.argmax(plan.candidates.p_dock))
    assert result.target_edge == plan.candidates.edges[best]
    assert np.array_equal(result.site, plan.candidates.aim[best])
    assert result.site_p_dock == plan.candidates.p_dock.max() < 0.999


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tool": [np.nan, 0.0]}, "tool position must be finite"),
        ({"tool": [0.0, 0.1, 0.2]}, "tool position must have shape"),
        ({"n_samples": 1}, "n_samples"),
        ({"n_samples": 2.5}, "n_samples"),
        ({"prior": np.zeros(8)}, "prior must be a GaussianShape"),
        ({"config": {"load": (0, -1)}}, "config must be a PlannerConfig"),
        ({"method": "magic"}, "unknown method"),
    ],
)
def test_bad_input_is_refused(kwargs, match):
    args = {"prior": SLOPER.prior, "tool": SLOPER.start, "config": CONFIG, **kwargs}
    with pytest.raises(ValueError, match=match):
        holds.evaluate_hold(**args)


@pytest.mark.parametrize("profile", ["mock", "robot"])
def test_perception_evaluates_with_the_planners_settings(profile, tmp_path):
    nodes = launch_nodes(profile, prior_source="problem")
    with node_from_launch(nodes["planner"], tmp_path) as (node, _):
        expected = node.config
    with node_from_launch(nodes["perception"], tmp_path) as (node, _):
        assert node.planner_config == expected
