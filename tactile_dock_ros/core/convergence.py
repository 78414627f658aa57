"""Between-chain convergence checks of MCMC draws: split R-hat, trapped chains, and which of
two chain groups sits where the posterior has its mass.

A chain seeded in a feasible pocket that the sampler cannot leave (HMC never crosses an
infeasible gap; the pocket may hold ~1e-5 of the posterior) keeps drawing from the pocket: its
draws are feasible, so no per-sample check sees it, but its mean sits far from the other
chains'. ``split_rhat`` measures the disagreement; ``trapped_chains`` names the chains;
``mass_gap`` says whether the chains it named hold more posterior mass than the others (then
the others are the trapped ones), or which of two groups (``chain_groups``) is trapped when
the chains disagree but none was named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

RHAT_LIMIT = 1.1  # split R-hat above this: the chains disagree (Gelman et al., BDA3 ch. 11)
RHAT_FALSE_ALARM = 0.01  # short chains: the limit rises to R-hat's 1 - this quantile for iid draws
TRAPPED_STD = 4.0  # a chain whose mean is this many robust posterior std off is trapped
MIN_DRAWS = 4  # per chain, for either check (two draws per split half)
MASS_GAP_LIMIT = 4.0  # standard errors: a chain group's log-mass score this far above: keep it


@dataclass(frozen=True)
class Convergence:
    """Convergence report of one ``sample_posterior`` call.

    Attributes:
        rhat: largest split R-hat over vertex coordinates of the returned draws (nan when the
            chains are too short to check, or the draws are independent, e.g. rejection).
        rhat_limit: the limit it was held to (``rhat_limit``).
        trapped: chains still flagged as trapped in the returned draws.
        reseeded: chains re-seeded (from other chains' states) and rerun, over all rounds.
        rounds: re-seed rounds run (0: the first run passed).
        mass_rounds: rounds whose chains to re-seed posterior mass chose (``mass_gap``), not
            the head count of ``trapped_chains``.
    """

    rhat: float = float("nan")
    rhat_limit: float = RHAT_LIMIT
    trapped: int = 0
    reseeded: int = 0
    rounds: int = 0
    mass_rounds: int = 0

    @property
    def converged(self) -> bool:
        """No trapped chain and R-hat within its limit (or not measurable)."""
        return self.trapped == 0 and not self.rhat > self.rhat_limit


def split_rhat(draws: np.ndarray) -> np.ndarray:
    """Per-coordinate split R-hat of draws (C chains, N steps, d) -> (d,); nan if N < MIN_DRAWS.

    Each chain is split into halves, then R = sqrt(var+ / W) with W the mean within-half
    variance and var+ = (n - 1) / n W + B / n (B / n the variance of the half means).
    Coordinates that vary in no half get 1 if the halves agree, inf if they do not.
    """
    x = np.asarray(draws, dtype=float)
    n, d = x.shape[1:]
    if n < MIN_DRAWS:
        return np.full(d, np.nan)
    half = n // 2
    parts = np.concatenate([x[:, :half], x[:, n - half :]], axis=0)  # (2C, half, d)
    within = parts.var(axis=1, ddof=1).mean(axis=0)
    between = parts.mean(axis=1).var(axis=0, ddof=1)  # B / n
    var_plus = (half - 1) / half * within + between
    with np.errstate(divide="ignore", invalid="ignore"):
        rhat = np.sqrt(var_plus / within)
    still = within <= 1e-300
    return np.where(still, np.where(between <= 1e-300, 1.0, np.inf), rhat)


def rhat_limit(chains: int, draws: int, coords: int) -> float:
    """The split R-hat limit for ``chains`` chains of ``draws`` draws in ``coords`` coordinates:
    RHAT_LIMIT, or, if larger, the value that the largest of the coordinates' R-hat exceeds
    with probability RHAT_FALSE_ALARM when every draw is independent.

    Decision: with few draws per chain (the node's 100 samples are 16 chains of 7) R-hat of
    perfectly mixed chains scatters well above 1.1 (median 1.12 over 24 coordinates), so a
    fixed limit would warn on most calls. For iid N(0, s^2) draws in k = 2C halves of h,
    R^2 = (h - 1) / h + F / h with F ~ F(k - 1, k (h - 1)) (between- over within-half
    variance); the limit takes F's 1 - RHAT_FALSE_ALARM / coords quantile (Bonferroni).
    """
    half = draws // 2
    k = 2 * chains
    if half < 2 or chains < 1:
        return RHAT_LIMIT
    f = stats.f.ppf(1 - RHAT_FALSE_ALARM / max(coords, 1), k - 1, k * (half - 1))
    return max(RHAT_LIMIT, float(np.sqrt((half - 1) / half + f / half)))


def _robust_centre_and_std(draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per coordinate of all draws (C, N, d): the median and 1.4826 x the median absolute
    deviation (a minority of trapped chains moves neither)."""
    flat = draws.reshape(-1, draws.shape[2])
    centre = np.median(flat, axis=0)
    return centre, 1.4826 * np.median(np.abs(flat - centre), axis=0)


def trapped_chains(draws: np.ndarray) -> np.ndarray:
    """Indices of chains (C, N, d) whose mean is more than TRAPPED_STD robust posterior
    standard deviations from the median chain mean in some coordinate (empty if N < MIN_DRAWS
    or if half the chains or more would be flagged: then no majority says where the
    posterior is).

    Decision: the robust std is 1.4826 x the median absolute deviation of all draws, so a
    minority of trapped chains does not widen it. A mixing chain's mean over N >= 4 draws
    lies within a couple of std of the centre; one 4 std off has (nearly) all its draws
    where the other chains put almost no mass. This treats a genuinely separate mode that
    only a minority of chains reached as a trap: with HMC no chain can cross into or out of
    it, so its share of the chains would reflect the seeding, not its posterior mass anyway.
    """
    x = np.asarray(draws, dtype=float)
    c, n = x.shape[:2]
    if n < MIN_DRAWS or c < 3:
        return np.zeros(0, dtype=int)
    centre, scale = _robust_centre_and_std(x)
    means = x.mean(axis=1)
    off = np.abs(means - np.median(means, axis=0))
    varies = scale > 1e-12 * (1 + np.abs(centre))
    far = np.any(varies & (off > TRAPPED_STD * np.where(varies, scale, 1.0)), axis=1)
    flagged = np.flatnonzero(far)
    return flagged if 2 * flagged.size < c else np.zeros(0, dtype=int)


def chain_groups(draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two groups of chains (C, N, d; C >= 2): the chain means, each coordinate in robust
    posterior std (as in ``trapped_chains``), projected on their first principal axis and
    split at the widest gap between neighbours (the smaller side first).

    Decision: ``trapped_chains`` can miss a pocket - two seeds shared round-robin put half the
    chains in it, and the robust std of that mixture spans both groups - while two clusters of
    chain means lie along one direction with the widest gap between them: on the late
    depth-prior cycle of ``chain_log_mass`` a cold run with 8 of 16 chains in a pocket (R-hat
    4.0, 2.7 std off) had no chain named, and this split found the seeds' two groups
    exactly.

    Decision: the projections are the top eigenvector of the chains' Gram matrix (C, C), which
    is the first principal axis' projection up to a positive scale. LAPACK's SVD (gesdd) did not
    converge on a finite, well-scaled 125 x 164 matrix of chain means (learned three_ledges
    prior, 2026-11-29, OpenBLAS on an AMD EPYC), which ended the cycle with an error."""
    x = np.asarray(draws, dtype=float)
    centre, scale = _robust_centre_and_std(x)
    means = x.mean(axis=1)
    means = (means - means.mean(axis=0)) / np.maximum(scale, 1e-12 * (1 + np.abs(centre)))
    projection = np.linalg.eigh(means @ means.T)[1][:, -1]
    order = np.argsort(projection, kind="stable")
    cut = int(np.argmax(np.diff(projection[order]))) + 1
    low, high = np.sort(order[:cut]), np.sort(order[cut:])
    return (low, high) if low.size <= high.size else (high, low)


def chain_log_mass(z_draws: np.ndarray) -> np.ndarray:
    """(C,) a score of the posterior mass of the region each chain of whitened draws
    (C, N, m; prior N(0, I)) samples, up to a constant shared by all chains: the sum over the m
    coordinates of the log of the chain's std, minus half its mean |z|^2; nan if N < MIN_DRAWS.

    Decision: for the posterior restricted to a region A - what a chain that cannot leave A
    samples - log P(A | H) = E[log phi(z)] + H(p_A) + const exactly (phi the prior density,
    H the entropy of the restricted posterior, const the log evidence). The entropy is taken
    as a Gaussian's with the chain's per-coordinate std: an upper bound, off in the same way
    for chains that sample alike. A pocket is both narrow and where the prior is thin: on a
    late depth-prior cycle (sloper truth 2, non-compliant, 103 rows, 16 chains of 7 draws)
    the 10 chains of a pocket scored 6.8 lower (median) than the 6 chains in the posterior's
    bulk; in five runs with no pocket the chain scores had a std of 0.7-1.7 (median 1.2).
    """
    z = np.asarray(z_draws, dtype=float)
    if z.shape[1] < MIN_DRAWS:
        return np.full(z.shape[0], np.nan)
    spread = np.log(np.maximum(z.std(axis=1, ddof=1), 1e-300)).sum(axis=1)
    return spread - 0.5 * np.mean(np.sum(z * z, axis=2), axis=1)


def mass_gap(z_draws: np.ndarray, group: np.ndarray, others: np.ndarray) -> float:
    """How much more posterior mass chains ``group`` hold than chains ``others`` (indices into
    C of whitened draws (C, N, m)): the difference of their mean ``chain_log_mass`` in
    standard errors (pooled within-group std of the chain scores); nan when it cannot be
    measured (fewer than MIN_DRAWS draws, or fewer than three chains in all).

    Decision: ``trapped_chains`` names the chains away from the median chain, i.e. the smaller
    group. Which group is smaller says nothing about mass when the chains were seeded by
    descent (seeds shared round-robin: one pocket seed can hold most chains; a cold run of the
    case in ``chain_log_mass`` kept the pocket that way, 5.2 std off without a warning). A gap
    beyond MASS_GAP_LIMIT moves chains between the groups to their shares of the mass
    (``sampling._mass_allocation``), whichever is larger; anything less keeps the head-count
    rule (a false alarm of a slowly mixing chain scores as the others do: random splits of the
    16 chains of five runs of that cycle with no pocket exceeded 3 in 0-2 %, 4 never; the
    pocket's split scored 7.4).
    """
    score = chain_log_mass(z_draws)
    a, b = score[np.asarray(group, dtype=int)], score[np.asarray(others, dtype=int)]
    dof = a.size + b.size - 2
    if a.size == 0 or b.size == 0 or dof < 1 or not np.all(np.isfinite(score)):
        return float("nan")
    pooled = np.sqrt((np.sum((a - a.mean()) ** 2) + np.sum((b - b.mean()) ** 2)) / dof)
    error = max(pooled, 1e-12) * np.sqrt(1.0 / a.size + 1.0 / b.size)
    return float((a.mean() - b.mean()) / error)
