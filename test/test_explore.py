"""Exploration loop (Sec. III-B) on seeded ground truths."""

import numpy as np
import pytest

from tactile_dock_ros.core import (
    constraints,
    episode_posterior,
    explore,
    planner,
    problems,
    sampling,
    simulate,
    slides,
)
from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.perception.config import PerceptionConfig
from tactile_dock_ros.perception.mock_camera import depth_prior
from tactile_dock_ros.tools import bringup


def _truth(name, want_feasible, first_seed=0):
    problem = problems.get(name)
    for seed in range(first_seed, first_seed + 50):  # bounded search for a matching instance
        truth = problem.sample_ground_truth(np.random.default_rng(seed))
        if simulate.feasible(problem, truth) == want_feasible:
            return problem, truth
    pytest.skip(f"no {'feasible' if want_feasible else 'infeasible'} {name} truth in 50 seeds")


@pytest.mark.parametrize("strategy", explore.STRATEGIES)
def test_feasible_episode_docks(strategy):
    # a bound with a wide margin, not one seed's coin: 12 sampler seeds x 3 strategies docked
    # in 1-3 cycles of the 15 allowed (2026-11-28)
    problem, truth = _truth("notch", True)
    result = explore.run_episode(problem, truth, strategy, np.random.default_rng(1), 15)
    assert result.outcome == "docked", result.message
    assert result.docked and not result.gave_up and result.cycles >= 1
    last = result.cycles_log[-1]
    assert last.docked and last.plan.decision == "dock"
    assert len(result.history) >= 2 and result.history.status[-1] != Status.FREE


def test_infeasible_episode_gives_up():
    # 12 sampler seeds gave up in 3 cycles of the 15 allowed (2026-11-28): a wide margin
    problem, truth = _truth("sloper", False)
    result = explore.run_episode(problem, truth, "ours", np.random.default_rng(2), 15)
    assert result.outcome == "gave_up", result.message
    assert result.gave_up and not result.docked
    assert result.cycles_log[-1].plan.decision == "give_up"


def test_infeasible_three_ledges_gives_up_once_its_slides_rule_out_every_hold():
    # benchmark truth 19: single samples with a short level edge between two observations of
    # one slide kept P_dock at 1/N = 0.01 for three more cycles before core.slides. Measured
    # (2026-11-28, 12 sampler seeds): 12 gave up, in 4 cycles (11) or 5 (1), samples rejected
    # by the slides in each; asserted with a margin over 3 seeds, never one seed's outcome.
    problem = problems.get("three_ledges")
    index = problems.names().index("three_ledges")
    truth = problem.sample_ground_truth(np.random.default_rng([0, index, 19]))
    assert not simulate.feasible(problem, truth)
    runs = [
        explore.run_episode(problem, truth, "ours", np.random.default_rng([0, index, 19, 1, s]), 8)
        for s in range(3)
    ]
    quick = [r for r in runs if r.outcome == "gave_up" and r.cycles <= 6]
    assert len(quick) >= 2, [(r.outcome, r.cycles) for r in runs]
    assert all(sum(c.rejected for c in r.cycles_log) > 0 for r in quick)


def _infeasible_bench_truth(name: str, instance: int, compliant: bool):
    """Problem, truth ``instance`` of ``bench docking`` (seed 0, infeasible in the mode), its
    depth prior as the bench perceives it, and the episode's sampler seed."""
    problem = problems.get(name)
    index = problems.names().index(name)
    truth = problem.sample_ground_truth(np.random.default_rng([0, index, instance]))
    assert not simulate.feasible(problem, truth, compliant=compliant)
    config = PerceptionConfig.load(bringup.PACKAGE_ROOT / "config/perception_mock.yaml")
    prior = depth_prior(truth, config, np.random.default_rng([0, index, instance, 2])).prior
    return problem, truth, prior, [0, index, instance, 1]


def test_infeasible_sloper_on_the_depth_prior_never_aims_at_a_site_twice():
    # benchmark truth 5, non-compliant: the planner re-planned a move already seen to slip
    # (probsim's fit kept 0.2-1 %, no sample docks) and ran to the cap before whole_path_p_dock.
    # Measured (2026-11-28, 12 sampler seeds): 9 gave up on the whole path in 5-9 cycles, 3 ran
    # to the cap of 10, no site was aimed at twice in any. The invariant is asserted on 2 seeds;
    # the give-up rate is a benchmark figure (bench docking), the rule is tested in test_planner.
    problem, truth, prior, seed = _infeasible_bench_truth("sloper", 5, compliant=False)
    for s in range(2):
        rng = np.random.default_rng([*seed, s])
        result = explore.run_episode(problem, truth, "ours", rng, 10, compliant=False, prior=prior)
        assert result.outcome in ("gave_up", "cycle_cap"), result.message
        aims = [tuple(np.round(c.plan.target_point, 3)) for c in result.cycles_log]
        aims = aims[:-1] if result.outcome == "gave_up" else aims
        assert len(set(aims)) == len(aims)  # no docking site tried twice


def _sloper_slide_episodes(seeds, cycles, spacing_m=None, monkeypatch=None):
    """Episodes on benchmark truth 1 (compliant, 0.24 degrees too steep: each slide runs down
    its 24 cm slope), one per sampler seed; ``spacing_m`` overrides the slide evidence's."""
    problem, truth, prior, seed = _infeasible_bench_truth("sloper", 1, compliant=True)
    if spacing_m is not None:
        monkeypatch.setattr(slides.crossed_piece_evidence, "__defaults__", (spacing_m,))
    return [
        explore.run_episode(
            problem, truth, "ours", np.random.default_rng([*seed, s]), cycles, prior=prior
        )
        for s in seeds
    ]


def test_a_slide_down_a_smooth_slope_is_evidence_on_every_few_centimetres(monkeypatch):
    # the first attempt is planned before any evidence, so both runs make the same first slide
    # (on any CPU): a row every 4 cm gives it more slip rows than one row per straight piece
    (dense,) = _sloper_slide_episodes([0], 2)
    (sparse,) = _sloper_slide_episodes([0], 2, 1.0, monkeypatch)
    assert np.array_equal(dense.cycles_log[0].plan.path, sparse.cycles_log[0].plan.path)
    first_rows = [r.cycles_log[1].history_length for r in (dense, sparse)]
    assert first_rows[0] > first_rows[1] > 0


@pytest.mark.slow
def test_slides_with_evidence_every_few_centimetres_teach_that_the_slope_slips(monkeypatch):
    # with one row per piece the other edges of the slope kept their chance to hold and P_dock
    # stayed at 0.7-0.9 to the cap. A row every 4 cm brings it below 0.5 (or to a give-up)
    # within the mock profile's 8 cycles in 21 of 28 sampler seeds (these 16 included: 12),
    # one row per piece in 5 (3); measured 2026-11-29 on an AMD EPYC. Outcomes differ between
    # CPUs (floating point): the claim is a difference of rates over 16 seeds with a margin
    # (binomial at those rates: it fails about once in 250 runs).
    seeds = range(100, 116)

    def fell(runs):
        return sum(min((c.plan.p_dock for c in r.cycles_log[1:]), default=0.0) < 0.5 for r in runs)

    dense = fell(_sloper_slide_episodes(seeds, 8))
    sparse = fell(_sloper_slide_episodes(seeds, 8, 1.0, monkeypatch))
    assert dense - sparse >= 3, (dense, sparse)


def test_a_non_compliant_slip_slides_on_as_evidence_with_slide_on_slip():
    # the same first attempt (planned before any evidence) slips on the 24 cm slope of bench
    # truth 1; with slide_on_slip it slides down to the lip, gives the slip rows of a compliant
    # slide from its move (one slide group) and does not dock
    problem, truth, prior, seed = _infeasible_bench_truth("sloper", 1, compliant=False)
    rng = [*seed, 0]
    runs = [
        explore.run_episode(
            problem, truth, "ours", np.random.default_rng(rng), 1, compliant=False,
            slide_on_slip=slide, prior=prior,
        )
        for slide in (False, True)
    ]  # fmt: skip
    assert np.array_equal(runs[0].cycles_log[0].plan.path, runs[1].cycles_log[0].plan.path)
    assert not any(r.docked for r in runs)
    rows = [r.history for r in runs]
    assert np.count_nonzero(rows[0].status == Status.SLIP_LEFT) == 1  # the first contact only
    slips = rows[1].status == Status.SLIP_LEFT
    assert np.count_nonzero(slips) >= 3
    groups = slides.slide_groups(rows[1], np.ones(len(rows[1]), int))
    assert len(groups) == 1 and len(groups[0]) == np.count_nonzero(slips)


def test_the_loop_draws_what_its_give_up_threshold_needs(monkeypatch):
    """With no edge holding in a later cycle's samples the loop's draws go on to the give-up's
    count (``episode_posterior.draw``'s ``hold_draws``, ``planner.give_up_draws``)."""
    asked = []
    real = episode_posterior.draw

    def spy(*args, **kwargs):
        asked.append(kwargs["hold_draws"])
        return real(*args, **kwargs)

    monkeypatch.setattr(episode_posterior, "draw", spy)
    problem, truth = _truth("sloper", False)
    for threshold in (1e-3, 1e-2):
        explore.run_episode(
            problem, truth, "ours", np.random.default_rng(2), 2, give_up_threshold=threshold
        )
    assert set(asked) == {3000, 300} and len(asked) >= 2


@pytest.mark.parametrize("give_up_samples", [400, 0])
def test_a_later_give_up_on_few_samples_is_planned_again_on_more(monkeypatch, give_up_samples):
    """After a contact, a give-up on fewer than ``give_up_samples`` samples draws on
    (``episode_posterior.draw_on``) and plans again on those samples followed by more; only
    that second answer counts. 0: the first give-up stands. (The planner here gives up on
    every history; the hold draws are off, so the draw-on is what adds samples.)"""
    calls = []
    real_plan, real_draw = planner.plan, episode_posterior.draw

    def gives_up_after_a_contact(vertices, prior, state, config):
        calls.append((len(state.history), vertices.copy()))
        if not len(state.history):
            return real_plan(vertices, prior, state, config)
        reason = "test: gives up"
        return planner.Plan("give_up", np.zeros((0, 2)), 0.0, 0.0, -1, reason, np.full(2, np.nan))

    monkeypatch.setattr(planner, "plan", gives_up_after_a_contact)
    monkeypatch.setattr(
        episode_posterior, "draw", lambda *a, **k: real_draw(*a, **k | {"hold_draws": 0})
    )
    problem, truth = _truth("sloper", False)
    result = explore.run_episode(
        problem, truth, "ours", np.random.default_rng(2), 3, compliant=False,
        give_up_samples=give_up_samples,
    )  # fmt: skip
    assert result.outcome == "gave_up" and result.cycles_log[-1].plan.reason == "test: gives up"
    later = [vertices for rows, vertices in calls if rows]
    if give_up_samples == 0:
        assert len(later) == 1 and len(later[0]) <= 100
        return
    assert len(later) == 2 and len(later[0]) <= 100  # planned again once, then gave up
    np.testing.assert_array_equal(later[1][: len(later[0])], later[0])
    assert 0.9 * give_up_samples <= len(later[1]) <= give_up_samples  # no slides: all kept


def test_a_bad_give_up_sample_count_is_refused():
    problem, truth = _truth("sloper", False)
    for bad in (-1, 2.5):
        with pytest.raises(ValueError, match="give_up_samples"):
            explore.run_episode(problem, truth, "ours", give_up_samples=bad)


def test_same_seed_same_episode():
    problem, truth = _truth("sloper", False)
    runs = [explore.run_episode(problem, truth, "ours", np.random.default_rng(5), 6) for _ in "ab"]
    assert runs[0].outcome == runs[1].outcome and runs[0].cycles == runs[1].cycles
    for a, b in zip(runs[0].cycles_log, runs[1].cycles_log, strict=True):
        assert np.array_equal(a.plan.path, b.plan.path)
    assert np.array_equal(runs[0].history.a, runs[1].history.a)


def test_errors_are_reported_not_raised():
    problem = problems.get("notch")
    truth = np.full((problem.prior.n_vertices, 2), np.nan)
    result = explore.run_episode(problem, truth, "ours", np.random.default_rng(0), 3)
    assert result.outcome == "error" and "ValueError" in result.message
    assert not result.docked and not result.gave_up


def test_bad_arguments_raise():
    problem = problems.get("notch")
    truth = problem.prior.mean_vertices
    with pytest.raises(ValueError):
        explore.run_episode(problem, truth, "random", np.random.default_rng(0))
    with pytest.raises(ValueError):
        explore.run_episode(problem, truth, "ours", np.random.default_rng(0), max_cycles=0)
    with pytest.raises(ValueError, match="give_up_threshold"):  # a planner setting
        explore.run_episode(problem, truth, "ours", np.random.default_rng(0), give_up_threshold=1)


def test_contradictory_history_still_plans():
    problem = problems.get("notch")
    mean = problem.prior.mean_vertices
    point = 0.5 * (mean[9] + mean[10])
    up, down = point + np.array([0, 0.1]), point - np.array([0, 0.1])
    history = History(  # passed freely through the surface, then stuck on it
        [up, point + np.array([0, 0.005])],
        [down, point - np.array([0, 0.005])],
        [Status.FREE, Status.STICK],
    )
    post = sampling.sample_posterior(problem.prior, history, 40, np.random.default_rng(0))
    state = EpisodeState(history, tool=problem.start).sampled(post.z, post.dropped)
    plan = explore.planner.plan(post.vertices, problem.prior, state, PlannerConfig(problem.load))
    assert plan.decision in ("dock", "give_up") and plan.reason


def test_plot_renders_an_episode(tmp_path):
    from tactile_dock_ros.tools import plot

    problem, truth = _truth("notch", True)
    result = explore.run_episode(problem, truth, "ours", np.random.default_rng(1), 3)
    out = tmp_path / "episode.png"
    plot.render(problem, truth, result, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_slide_evidence_follows_the_slide_and_fits_the_truth():
    # a slab steeper than the friction angle with a lip: a push near the top slides to the lip
    problem = problems.get("notch")
    truth = problem.prior.mean_vertices
    x0 = -0.16  # on slab 1 (45 degrees), 2 cm below its notch and 10 cm above its lip
    path = np.array([[x0, 0.45], [x0, -0.5]])
    run = simulate.guarded_path(truth, False, path, problem.friction, problem.load, True, 0.01)
    assert not run.docked and run.stop_feature.kind == "vertex"
    evidence = explore.slide_evidence(truth, False, run, problem.load, 0.01)
    added = len(evidence) - len(run.observations)
    slid = abs(run.stop_feature.index - int(np.argmin(np.abs(truth[:, 0] - x0))))
    assert added >= max(slid - 2, 1)  # one observation per edge crossed completely
    new = evidence.subset(np.arange(len(evidence)) >= len(run.observations))
    assert np.all(new.status == run.observations.status[-1])
    assert constraints.history_consistent(False, truth[None], evidence, problem.friction)[0]
    # a contact-free run adds nothing
    away = np.array([[x0, 0.45], [x0, 0.5]])
    free = simulate.guarded_path(truth, False, away, problem.friction, problem.load)
    assert len(explore.slide_evidence(truth, False, free, problem.load, 0.01)) == len(
        free.observations
    )
