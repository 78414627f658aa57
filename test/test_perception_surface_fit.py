"""Empirical Bayes of the surface model (perception.surface_fit): recovery on data drawn from it."""

import numpy as np
import pytest

from tactile_dock_ros.perception import surface_fit
from tactile_dock_ros.perception.surface_fit import Differences, Mixture, Run


def _template(seed=0, runs=160):
    """Runs shaped like the mock camera's: 2 cm spacing, 10-40 vertices, vertex noise 0.5-2 mm
    along the normal, a third of the ends at a depth jump (their row dropped)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(runs):
        r = int(rng.integers(10, 41))
        s2 = (1e-3 * np.exp(rng.uniform(np.log(0.5), np.log(2.0), r))) ** 2
        keep = np.ones(r - 2, bool)
        keep[[0, -1]] = rng.random(2) > 1 / 3
        out.append(Run(s2, np.zeros(r - 2), keep, 0.02))
    return out


def _dense_noise(run) -> np.ndarray:
    """(m, m) covariance of a run's m second differences from its vertex noise (dense)."""
    m = len(run.c)
    D2 = np.zeros((m, m + 2))
    D2[np.arange(m), np.arange(m)] = 1.0
    D2[np.arange(m), np.arange(m) + 1] = -2.0
    D2[np.arange(m), np.arange(m) + 2] = 1.0
    return (D2 * run.s2) @ D2.T


def test_pairs_carry_the_band_of_the_second_differences_noise():
    runs = _template(runs=3)
    d = Differences.from_runs(runs)
    offset = 0
    for r in runs:
        B = _dense_noise(r)
        kept = np.flatnonzero(r.keep)
        np.testing.assert_allclose(d.noise[offset : offset + len(kept)], np.diag(B)[kept])
        for a in range(len(kept)):
            for b in range(a + 1, len(kept)):
                mask = (d.first == offset + a) & (d.second == offset + b)
                assert mask.sum() == (kept[b] - kept[a] <= 2)
                if mask.any():
                    assert d.pair_noise[mask][0] == pytest.approx(B[kept[a], kept[b]])
        offset += len(kept)
    assert offset == len(d.c)


def test_smoother_evidence_is_the_dense_gaussian_density():
    rng = np.random.default_rng(3)
    runs = surface_fit.sample_runs(_template(runs=4), Mixture(0.05, 0.1, 0.5, 1.0), rng)
    expected = 0.0
    for r in runs:
        B = _dense_noise(r)[np.ix_(r.keep, r.keep)]
        c = r.c[r.keep]
        q = surface_fit.smoother_turn_variance(c, np.diag(B), 0.02, 0.1, 2.0)
        cov = 0.81 * B + np.diag(q)
        _, logdet = np.linalg.slogdet(cov)
        expected += -0.5 * (c @ np.linalg.solve(cov, c) + logdet + len(c) * np.log(2 * np.pi))
    assert surface_fit.smoother_log_evidence(runs, 0.1, 2.0, 0.9) == pytest.approx(expected)


@pytest.mark.parametrize(
    "true",
    [Mixture(0.05, 0.1, 0.5, 0.9), Mixture(0.1, 0.03, 1.0, 1.1)],
    ids=["stiff-faces-low-noise", "bent-faces-rare-corners"],
)
def test_fit_recovers_the_model_it_was_drawn_from(true):
    """About 4,000 second differences drawn from the spike-and-slab with correlated noise."""
    runs = surface_fit.sample_runs(_template(), true, np.random.default_rng(1))
    fit = surface_fit.fit_mixture(Differences.from_runs(runs))
    got = fit.mixture
    assert not fit.at_bounds
    assert got.bend_sigma_rad == pytest.approx(true.bend_sigma_rad, rel=0.12)
    assert got.corner_fraction == pytest.approx(true.corner_fraction, abs=0.02)
    assert got.corner_sigma_rad == pytest.approx(true.corner_sigma_rad, rel=0.25)
    assert got.noise_scale == pytest.approx(true.noise_scale, rel=0.06)


def test_without_corners_the_smoother_gets_the_bend_and_no_corners():
    """pi = 0, kappa = 1: the smoother's family holds the model (threshold -> no corners)."""
    true = Mixture(0.04, 1e-4, 0.4, 1.0)
    runs = surface_fit.sample_runs(_template(seed=2), true, np.random.default_rng(2))
    fit = surface_fit.fit_surface(runs, surface_fit.SurfaceParams())
    assert fit.mixture.mixture.bend_sigma_rad == pytest.approx(0.04, rel=0.12)
    assert fit.bend_sigma_rad == pytest.approx(0.04, rel=0.12)
    assert fit.corner_threshold >= 3.0
    assert fit.score["after"] >= fit.score["before"]


def test_the_projection_finds_corners_where_the_model_has_them():
    """A clear slab (5 % corners of 0.5 rad over faces of 0.02 rad): a threshold that detects
    them (below 3 noise stds), a bend near the faces', a better score than the hand-set 0.1 / 2."""
    true = Mixture(0.02, 0.05, 0.5, 1.0)
    runs = surface_fit.sample_runs(_template(seed=4), true, np.random.default_rng(4))
    fit = surface_fit.fit_surface(runs, surface_fit.SurfaceParams())
    assert fit.corner_threshold < 3.0
    assert 0.01 < fit.bend_sigma_rad < 0.04
    assert fit.score["after"] > fit.score["before"]
