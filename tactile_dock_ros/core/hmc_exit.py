"""Each HMC chain's first exit from the feasible set in its look-ahead window, compiled.

The HMC loop (``sampling.hmc_chains``) needs, per chain and window [0, span], the end of the
feasible interval that contains t = 0 (Sec. IV-E, Alg. 1): the roots of the primitives that
may vanish, sorted, and the first segment whose midpoint violates an observation. The numpy
version of this search (``intervals.ellipse_roots`` + ``segment_edges``, then every chain's
segments judged in chunks) spent ~55 % of the HMC loop (~45 % of a three_ledges cycle) in a
few dozen array calls per iteration for ~10 roots and a handful of segments per chain. Here
each chain is one compiled loop that solves its roots, walks its segments in time order and
stops at the first infeasible one. Decision (not in the paper): numba, compiled on first use
and cached next to this file; the roots come from the same solvers as the batched interval
algebra's (``roots.quartic``: Ferrari closed form, Newton polish, companion-matrix eigenvalues
where the closed form is unreliable or misses a sign change across the window), so the draws
match the numpy search up to rounding. numba invalidates a cached function when its own file
changes, not when a function it calls from another file does: after editing ``roots.py`` in a
work tree, delete ``core/__pycache__/*.nb?`` (an installed package never changes under its
cache).

Segment judging (the ``live`` pairs of ``HistoryConstraints.live_pairs``): a free
observation is violated where any of its live pairs is crossed (pair value > 0), a contact
observation where all of its live pairs are unsatisfied, and a contact observation without a
live pair from the window's start. ``plain`` systems (``LinearConstraints``) have one primitive
per pair and observation, violated where it is > 0.
"""

from __future__ import annotations

import numba
import numpy as np

from .intervals import ROOT_MIN_TIME, trig_to_quartic
from .roots import quadratic, quadratic_batch, quartic, quartic_batch

# value of an inactive pair slot: far below any primitive's, so the pair's max / min structure
# ignores it as it would -inf, without inf arithmetic in products
INACTIVE = -1e300


@numba.njit(cache=True, error_model="numpy")
def _window_roots(coef, solve, span, to_quartic, phi, all_linear, times, owners):
    """Roots in (ROOT_MIN_TIME, span) of one chain's solved primitives, sorted; their count."""
    n = 0
    x = np.empty(4)
    poly = np.empty(5)
    lo = np.tan(0.5 * (ROOT_MIN_TIME - phi))
    hi = np.tan(0.5 * (span - phi))
    for k in range(coef.shape[1]):
        if not solve[k]:
            continue
        if all_linear:
            quadratic(coef[0, k] - coef[1, k], 2 * coef[2, k], coef[0, k] + coef[1, k], x)
            found, shift = 2, 0.0
        else:
            for j in range(5):
                acc = 0.0
                for i in range(5):
                    acc += coef[i, k] * to_quartic[i, j]
                poly[j] = acc
            quartic(poly, lo, hi, x)
            found, shift = 4, phi
        for i in range(found):
            if np.isnan(x[i]):
                continue
            t = shift + 2 * np.arctan(x[i])
            if t > ROOT_MIN_TIME and t < span:
                times[n], owners[n] = t, k
                n += 1
    order = np.argsort(times[:n], kind="mergesort")
    times[:n], owners[:n] = times[:n][order], owners[:n][order]
    return n


@numba.njit(cache=True, error_model="numpy")
def _segment_violated(coef, t, live_pairs, n_live, structure, g):
    """Whether any observation is violated at time t, judged on the live pairs (sorted by
    observation); g (6,) is scratch space."""
    pair_prims, pair_obs, pair_free, _, plain = structure
    cos, sin = np.cos(t), np.sin(t)
    basis = (cos, sin, 2 * cos * cos - 1, 2 * sin * cos)  # as ``intervals.trig_basis``
    i = 0
    while i < n_live:
        obs = pair_obs[live_pairs[i]]
        free = pair_free[live_pairs[i]]
        crossed, unsatisfied = False, True  # free: any pair > 0; contact: all pairs > 0
        while i < n_live and pair_obs[live_pairs[i]] == obs:
            p = live_pairs[i]
            g[:] = INACTIVE
            for j in range(pair_prims.shape[1]):
                k = pair_prims[p, j]
                if k >= 0:
                    g[j] = (
                        coef[0, k]
                        + coef[1, k] * basis[0]
                        + coef[2, k] * basis[1]
                        + coef[3, k] * basis[2]
                        + coef[4, k] * basis[3]
                    )
            if plain:
                value = g[0]
            else:
                gmax = max(max(g[0], g[1]), max(g[2], g[3]))
                gmin = min(min(g[0], g[1]), min(g[2], g[3]))
                value = max(-gmax, gmin) if free else max(gmax, max(g[4], g[5]))
            if value > 0:
                crossed = True
            else:
                unsatisfied = False
            i += 1
        if crossed if (free or plain) else unsatisfied:
            return True
    return False


@numba.njit(cache=True, error_model="numpy")
def first_exits(coef, solve, live, span, phi, to_quartic, all_linear, structure):
    """Per chain c (coef (C, 5, K), solve (C, K), live (C, P), span (C,)): whether it leaves
    the feasible set in (0, span[c]), when (the root that ends the feasible interval that
    holds t = 0; span where it does not leave), the primitive that root belongs to (-1 if it
    does not leave or is infeasible from the start) and whether the first segment is already
    infeasible (numerical grazing). Quartics are solved in time shifted by phi,
    ``to_quartic`` = ``intervals.trig_to_quartic(phi)``; ``structure`` is the system's
    ``exit_structure``: per-pair primitives (P, slots; -1 inactive), observation and
    free flag, per-observation contact flag, and whether the system is plain."""
    pair_obs, contact_obs = structure[1], structure[3]
    n_chains, n_prims = coef.shape[0], coef.shape[2]
    hit = np.zeros(n_chains, dtype=np.bool_)
    stuck = np.zeros(n_chains, dtype=np.bool_)
    dt = span.copy()
    owner = np.full(n_chains, -1)
    times = np.empty(4 * n_prims)
    owners = np.empty(4 * n_prims, dtype=np.int64)
    live_pairs = np.empty(live.shape[1], dtype=np.int64)
    covered = np.zeros(contact_obs.shape[0], dtype=np.bool_)
    g = np.empty(6)
    for c in range(n_chains):
        n_live = 0
        covered[:] = False
        for p in range(live.shape[1]):
            if live[c, p]:
                live_pairs[n_live] = p
                n_live += 1
                covered[pair_obs[p]] = True
        blocked = False  # a contact observation without live pairs: violated throughout
        for o in range(contact_obs.shape[0]):
            if contact_obs[o] and not covered[o]:
                blocked = True
        if blocked:
            hit[c], stuck[c], dt[c] = True, True, 0.0
            continue
        n = _window_roots(coef[c], solve[c], span[c], to_quartic, phi, all_linear, times, owners)
        start = 0.0
        for s in range(n + 1):
            end = times[s] if s < n else span[c]
            mid = 0.5 * (start + end)
            if _segment_violated(coef[c], mid, live_pairs, n_live, structure, g):
                hit[c], dt[c] = True, start
                if s == 0:
                    stuck[c] = True
                else:
                    owner[c] = owners[s - 1]
                break
            start = end
    return hit, dt, owner, stuck


def structure(pair_prims, pair_obs, pair_free, contact_obs, plain: bool) -> tuple:
    """``first_exits``' structure argument (see there), C-contiguous with fixed dtypes, so that
    every system uses the one compiled signature."""
    return (
        np.ascontiguousarray(pair_prims, dtype=np.int64),
        np.ascontiguousarray(pair_obs, dtype=np.int64),
        np.ascontiguousarray(pair_free, dtype=bool),
        np.ascontiguousarray(contact_obs, dtype=bool),
        bool(plain),
    )


def warm_up() -> None:
    """Compile ``first_exits`` for the HMC loop's argument types and the batched root solvers
    of the line scans (``roots``: Gibbs, seeding descents), or load them from the cache
    (``__pycache__`` next to this file, else numba's user-wide cache): the first call after an
    installation compiles for ~10 s, later processes load it in well under a second. The
    inference node calls this at start-up, so that its first posterior is not the one that
    waits."""
    phi = 0.05
    first_exits(
        np.zeros((1, 5, 1)),
        np.ones((1, 1), dtype=bool),
        np.ones((1, 1), dtype=bool),
        np.full(1, 2 * phi),
        phi,
        trig_to_quartic(phi),
        False,
        structure(np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1), False),
    )
    quadratic_batch(np.ones(1), np.zeros(1), -np.ones(1))
    quartic_batch(np.ones((1, 5)), np.zeros(1), np.ones(1))
