"""A seeding descent step's segments judged, compiled (``sampling._descent_step``).

On a depth prior a descent step's coordinate line, over +- 3 std, crosses ~1000 primitive roots
per chain (sloper: 900-3900 primitives, and a basis column moves many vertices at once), and
its segments are judged twice: the picked observation at every midpoint (segments that fix it
are preferred) and every observation at the ~33 candidate midpoints (the violated counts). In
numpy these were gathers over (chains, pairs, segments): 2.9 and 2.6 ms of a step's 9.3 ms
timed piece by piece (8.5 ms as a whole; 40 captured steps of a sloper depth-prior run,
one-off timing; 4.0 ms now). Here each is one compiled loop, with the pair rule of the HMC
window search (``hmc_exit.pair_value``); for finite values the verdicts equal the numpy
reduction's (``PairStructure.reduce_pairs``) bit for bit. Along the line a primitive is
q0 + t (q1 + t q2) (``line_coefficients``, (C, K, 3)); ``structure`` is the system's
``exit_structure`` (pairs sorted by observation). numba's cache does not notice edits of
``hmc_exit.pair_value``: delete ``core/__pycache__/*.nb?`` after one (see ``hmc_exit``).
"""

from __future__ import annotations

import numba
import numpy as np

from .hmc_exit import INACTIVE, pair_value, structure
from .roots import line_roots


@numba.njit(cache=True, error_model="numpy")
def _observation_violated(src, t, on_line, obs, first, last, structure, g):
    """Whether observation ``obs`` (pairs first..last-1) is violated: a free observation where
    any pair is > 0, a contact observation where every pair is (one without pairs: always), as
    ``PairStructure.reduce_pairs``. Primitive k's value is src[k, 0] + t (src[k, 1] + t
    src[k, 2]) at parameter t of a line (``on_line``, src (K, 3)), else src[k, 0] (values
    (K, 1)); g (6,) is scratch space."""
    pair_prims, _, pair_free, contact_obs, plain = structure
    if first == last:
        return contact_obs[obs]
    any_crossed = pair_free[first] or plain
    for p in range(first, last):
        g[:] = INACTIVE
        for j in range(pair_prims.shape[1]):
            k = pair_prims[p, j]
            if k >= 0:
                g[j] = src[k, 0] + t * (src[k, 1] + t * src[k, 2]) if on_line else src[k, 0]
        if (pair_value(g, pair_free[p], plain) > 0) == any_crossed:
            return any_crossed
    return not any_crossed


@numba.njit(cache=True, error_model="numpy")
def picked_violated(coef, mids, pick, structure):
    """(C, S): whether observation ``pick[c]`` is violated at parameter ``mids[c, s]`` of row
    c's line (coef (C, K, 3))."""
    pair_obs = structure[1]
    out = np.empty(mids.shape, dtype=np.bool_)
    g = np.empty(6)
    for c in range(mids.shape[0]):
        first = np.searchsorted(pair_obs, pick[c])
        last = np.searchsorted(pair_obs, pick[c], side="right")
        for s in range(mids.shape[1]):
            out[c, s] = _observation_violated(
                coef[c], mids[c, s], True, pick[c], first, last, structure, g
            )
    return out


@numba.njit(cache=True, error_model="numpy")
def violated_counts(values, structure, cap):
    """(N,): how many observations are violated, from primitive values (N, K); counting stops
    above ``cap[n]`` (cap[n] + 1 is returned then): a descent step only needs the candidates
    at or below the current segment's count."""
    pair_obs, n_obs = structure[1], structure[3].shape[0]
    bounds = np.searchsorted(pair_obs, np.arange(n_obs + 1))
    out = np.zeros(values.shape[0], dtype=np.int64)
    g = np.empty(6)
    for n in range(values.shape[0]):
        src = values[n].reshape(-1, 1)
        for o in range(n_obs):
            if out[n] > cap[n]:
                break
            if _observation_violated(src, 0.0, False, o, bounds[o], bounds[o + 1], structure, g):
                out[n] += 1
    return out


def warm_up() -> None:
    """Compile the seeding descent's kernels and the line scans' roots (``roots.line_roots``,
    also Gibbs') or load them from the cache, as ``hmc_exit.warm_up`` (the inference node
    calls both at start-up)."""
    plain = structure(np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1), True)
    coef = np.zeros((1, 1, 3))
    line_roots(coef, np.zeros(1), np.ones(1))
    picked_violated(coef, np.zeros((1, 1)), np.zeros(1, dtype=np.int64), plain)
    violated_counts(np.zeros((1, 1)), plain, np.zeros(1, dtype=np.int64))
