"""Constraint systems with states on both sides of their feasible sets, shared by the tests of
the compiled kernels (``hmc_exit``, ``descent_scan``) against the numpy interval algebra."""

import numpy as np

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.constraint_systems import HistoryConstraints, LinearConstraints
from tactile_dock_ros.core.constraints import prune_pairs
from tactile_dock_ros.core.sampling import sample_posterior
from tactile_dock_ros.core.sampling_problems import probe_history


def history_system(name: str, seed: int, probes) -> tuple[HistoryConstraints, np.ndarray]:
    """A problem's system for probes on a drawn truth; 48 posterior draws (feasible) and 16
    prior draws (starts that violate observations)."""
    problem = problems.get(name)
    truth = problem.sample_ground_truth(np.random.default_rng(seed))
    history = probe_history(problem, truth, probes)
    shape = problem.prior
    system = HistoryConstraints(shape, history, prune_pairs(shape, history, 1e-4))
    posterior = sample_posterior(shape, history, 48, np.random.default_rng(4)).z
    return system, np.vstack([posterior, shape.sample_z(np.random.default_rng(6), 16)])


def linear_system() -> tuple[LinearConstraints, np.ndarray]:
    """Random half-spaces around the origin, and 48 states at the origin (feasible)."""
    rng = np.random.default_rng(7)
    F = rng.standard_normal((80, 6))
    return LinearConstraints(F, -rng.uniform(0.2, 1.5, 80)), np.zeros((48, 6))
