"""Reference posterior by sequential Monte Carlo: an independent check of the MCMC samplers.

The posterior of eq. (13) is the Gaussian prior restricted to the set where every history
observation holds (f_H <= 0). Where plain rejection is hopeless (a depth prior after a few
cycles: first-cycle acceptance ~5e-5, later ones far less), ``smc_posterior`` reaches it by
tempering: particles drawn from the prior are carried through

    pi_t(z) ~ N(z; 0, I) exp(-lam_t V(z)),   V(z) = sum_j max(f_j(z), 0),   0 = lam_0 < lam_1 ...

then through the exact indicator 1[V(z) = 0], re-weighted, resampled and moved at every stage
by elliptical slice sampling (Murray, Adams & MacKay 2010), which leaves each pi_t invariant for
a Gaussian prior with no step size to tune. Nothing here is shared with ``sampling``'s seeding
or HMC (only the exact constraint values of ``constraints.observation_violations``), so where
the two agree the posterior is confirmed, and where they do not, one of them is wrong.

Decisions (the paper has no SMC): the next lam keeps the effective sample size of the
incremental weights at ``ess_fraction`` of the particles (bisection in log lam); the
indicator stage starts once that many particles already satisfy every row. The weights also
estimate log P(H) (the evidence), reported for information. Unlike MCMC chains, particles keep
the relative mass of separate feasible pockets (the re-weighting sees the mass), which is what
the seeding of ``sampling`` cannot guarantee; the price is time: seconds to minutes, a
benchmark tool, not a per-cycle sampler.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .constraints import observation_primitives, observation_violations
from .history import History
from .shape import GaussianShape

LOG = logging.getLogger(__name__)

SHRINK_LIMIT = 60  # elliptical slice bracket shrinks per move; then the particle stays put


@dataclass(frozen=True)
class ReferencePosterior:
    """Outcome of ``smc_posterior``: equally weighted draws ``z`` (N, m) satisfying every row."""

    z: np.ndarray
    log_evidence: float  # log P(H) under the prior (the SMC estimate)
    stages: int  # tempering stages, the indicator stage included


def total_violation(
    shape: GaussianShape, history: History, z: np.ndarray, primitives=None
) -> np.ndarray:
    """V(z) (N,): the summed positive parts of the observation values f_j (0 = consistent);
    ``primitives`` as ``constraints.observation_violations`` takes them."""
    values = observation_violations(
        shape.closed, shape.vertices(z), history, shape.friction, primitives
    )
    return np.sum(np.maximum(values, 0.0), axis=1)


def _slice_moves(shape, history, primitives, z, violation, lam, moves, rng):
    """``moves`` elliptical slice moves of every particle under exp(-lam V) (lam = inf: the
    indicator); returns the moved z and their V."""
    n, m = z.shape
    for _ in range(moves):
        nu = rng.standard_normal((n, m))
        level = -lam * violation + np.log(rng.uniform(size=n)) if np.isfinite(lam) else None
        theta = rng.uniform(0.0, 2.0 * np.pi, size=n)
        low, high = theta - 2.0 * np.pi, theta.copy()
        todo = np.arange(n)
        for _ in range(SHRINK_LIMIT):
            c, s = np.cos(theta[todo])[:, None], np.sin(theta[todo])[:, None]
            proposal = z[todo] * c + nu[todo] * s
            v = total_violation(shape, history, proposal, primitives)
            ok = v <= 0.0 if level is None else -lam * v > level[todo]
            z[todo[ok]], violation[todo[ok]] = proposal[ok], v[ok]
            todo, th = todo[~ok], theta[todo[~ok]]
            if todo.size == 0:
                break
            low[todo] = np.where(th < 0.0, th, low[todo])
            high[todo] = np.where(th < 0.0, high[todo], th)
            theta[todo] = rng.uniform(low[todo], high[todo])
    return z, violation


def _log_mean_exp(x: np.ndarray) -> float:
    top = float(np.max(x))
    return top + float(np.log(np.mean(np.exp(x - top)))) if np.isfinite(top) else -np.inf


def _next_lambda(violation, lam, ess_fraction):
    """Smallest step from lam whose incremental weights exp(-(lam' - lam) V) keep ESS at
    ``ess_fraction`` (bisection on log lam'); inf when the indicator itself keeps that much."""
    target = ess_fraction * len(violation)
    if np.mean(violation <= 0.0) >= ess_fraction:
        return np.inf

    def ess(step):
        w = np.exp(-step * (violation - violation.min()))
        return w.sum() ** 2 / np.sum(w * w)

    lo, hi = 0.0, max(1.0, 2.0 * lam) / max(float(np.median(violation)), 1e-300)
    while ess(hi) > target:
        lo, hi = hi, 2.0 * hi
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess(mid) > target else (lo, mid)
    return lam + hi


def smc_posterior(
    shape: GaussianShape,
    history: History,
    n_particles: int,
    rng: np.random.Generator,
    *,
    moves: int = 10,
    final_moves: int = 30,
    ess_fraction: float = 0.5,
    max_stages: int = 200,
) -> ReferencePosterior:
    """Draws of P(z | H) (eq. 13) by tempered SMC with elliptical slice moves (module doc).

    ``moves`` slice moves per particle after each resampling, ``final_moves`` after the
    indicator stage. Raises ValueError on bad settings and RuntimeError when ``max_stages``
    stages do not reach the indicator (the history has (almost) no prior mass).
    """
    if n_particles < 2 or moves < 1 or final_moves < 0 or max_stages < 1:
        raise ValueError("need n_particles >= 2, moves >= 1, final_moves >= 0, max_stages >= 1")
    if not 0.0 < ess_fraction < 1.0:
        raise ValueError(f"ess_fraction must lie in (0, 1), got {ess_fraction}")
    if shape.n_basis == 0:
        raise ValueError("the shape has no basis columns: nothing to sample")
    primitives = observation_primitives(history, shape.friction)
    z = shape.sample_z(rng, n_particles)
    violation = total_violation(shape, history, z, primitives)
    lam, log_evidence = 0.0, 0.0
    for stage in range(1, max_stages + 1):
        new = _next_lambda(violation, lam, ess_fraction)
        if np.isfinite(new):
            log_w = -(new - lam) * violation
        else:
            log_w = np.where(violation <= 0.0, 0.0, -np.inf)
        log_evidence += _log_mean_exp(log_w)
        w = np.exp(log_w - log_w.max())
        pick = rng.choice(n_particles, size=n_particles, p=w / w.sum())
        distinct = len(np.unique(pick)) / n_particles
        z, violation, lam = z[pick], violation[pick], new
        count = moves if np.isfinite(lam) else final_moves
        z, violation = _slice_moves(shape, history, primitives, z, violation, lam, count, rng)
        LOG.info("smc stage %d: lambda %.3g, %.0f%% distinct", stage, lam, 100 * distinct)
        if not np.isfinite(lam):
            return ReferencePosterior(z, log_evidence, stage)
    raise RuntimeError(f"SMC did not reach the history's constraint set in {max_stages} stages")
