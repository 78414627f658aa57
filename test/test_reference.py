"""The SMC reference posterior (core.reference) against exact rejection draws."""

import numpy as np
import pytest

from tactile_dock_ros.core import explore, problems, reference, sampling
from tactile_dock_ros.core.history import History
from tactile_dock_ros.core.shape import GaussianShape


@pytest.fixture(scope="module")
def sloper_cycle():
    """Sloper's first-cycle history (9 rows; about 1 prior draw in 200 satisfies it) and
    exact draws of its posterior by rejection."""
    problem = problems.get("sloper")
    truth = problem.sample_ground_truth(np.random.default_rng([5, 0]))
    history = explore.run_episode(problem, truth, "ours", np.random.default_rng(0), 1).history
    z = problem.prior.sample_z(np.random.default_rng(1), 150_000)
    exact = z[sampling._consistent_rows(problem.prior, history, z)]
    return problem.prior, history, exact, len(exact) / len(z)


def test_smc_matches_rejection_means_spreads_and_evidence(sloper_cycle):
    shape, history, exact, acceptance = sloper_cycle
    assert len(history) >= 5 and len(exact) >= 500
    result = reference.smc_posterior(shape, history, 400, np.random.default_rng(3))
    assert result.stages >= 3  # tempered, not one rejection step
    assert np.all(sampling._consistent_rows(shape, history, result.z))
    mean, std = exact.mean(axis=0), exact.std(axis=0)
    # the prior is 1.0 std off in its worst mean and up to 3.4x wider: these bounds see it
    assert np.max(np.abs(result.z.mean(axis=0) - mean) / std) < 0.35
    assert np.all((0.75 < result.z.std(axis=0) / std) & (result.z.std(axis=0) / std < 1.33))
    assert result.log_evidence == pytest.approx(np.log(acceptance), abs=0.4)


def test_an_empty_history_gives_prior_draws():
    shape = problems.get("notch").prior
    result = reference.smc_posterior(shape, History(), 2000, np.random.default_rng(0))
    assert result.stages == 1 and result.log_evidence == 0.0
    assert np.all(np.abs(result.z.mean(axis=0)) < 0.1)
    assert np.all(np.abs(result.z.std(axis=0) - 1.0) < 0.1)


def test_total_violation_is_zero_exactly_on_consistent_states(sloper_cycle):
    shape, history, exact, _ = sloper_cycle
    z = np.vstack([exact[:50], shape.sample_z(np.random.default_rng(4), 200)])
    violation = reference.total_violation(shape, history, z)
    assert np.all(violation >= 0)
    np.testing.assert_array_equal(violation == 0, sampling._consistent_rows(shape, history, z))


@pytest.mark.parametrize(
    "settings",
    [
        {"n_particles": 1},
        {"moves": 0},
        {"final_moves": -1},
        {"ess_fraction": 1.0},
        {"ess_fraction": 0.0},
        {"max_stages": 0},
    ],
)
def test_bad_settings_are_refused(sloper_cycle, settings):
    shape, history, _, _ = sloper_cycle
    kwargs = {"n_particles": 100, **settings}
    n = kwargs.pop("n_particles")
    with pytest.raises(ValueError):
        reference.smc_posterior(shape, history, n, np.random.default_rng(0), **kwargs)


def test_a_shape_without_basis_and_too_few_stages_are_errors(sloper_cycle):
    shape, history, _, _ = sloper_cycle
    fixed = GaussianShape(shape.mean, np.zeros((shape.mean.size, 0)))
    with pytest.raises(ValueError, match="basis"):
        reference.smc_posterior(fixed, history, 100, np.random.default_rng(0))
    with pytest.raises(RuntimeError, match="stages"):
        reference.smc_posterior(shape, history, 100, np.random.default_rng(0), max_stages=1)
