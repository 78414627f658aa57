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
changes, not when a function it calls from another file does: after editing ``roots.py`` (or
this file, whose ``pair_value`` ``descent_scan`` calls) in a work tree, delete
``core/__pycache__/*.nb?`` (an installed package never changes under its cache).

The coefficients and the window filter are compiled too (2026-11-27, d6c96f4). On an iteration of a
late depth-prior three_ledges cycle (16 chains, 7760 primitives of 1691 pairs on 61 edges;
one-off timing) the numpy coefficients (C, 5, K) (two (C, m) x (m, K) products), their
Bernstein filter and the live pairs took ~9 ms of the iteration's 9.6 ms, the exit search
0.6 ms, though under 1 % of the primitives were then solved. A primitive's coefficients
need only its edge's end displacements A z0, A p (4 numbers each, ``ellipse_terms``: one
small matrix product per iteration) and quadratic terms, so each chain builds them in one
pass with the filter, a slope bound settling most primitives before the Bernstein test, and
nothing of size (C, K) is stored: 3.1-3.7 ms for the same iteration (several timings).

Segment judging (the ``live`` pairs, see ``_chain_window``): a free observation is violated
where any of its live pairs is crossed (pair value > 0), a contact observation where all of
its live pairs are unsatisfied, and a contact observation without a live pair from the
window's start. ``plain`` systems (``LinearConstraints``) have one primitive per pair and
observation, violated where it is > 0.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from .intervals import ROOT_MIN_TIME, TRIG_TO_POLY, trig_to_quartic
from .roots import quadratic, quartic

# power -> Bernstein coefficients on [0, 1] of a quartic: b_i = sum_l C(i,l)/C(4,l) c_l
POWER_TO_BERNSTEIN = np.array(
    [
        [1, 0, 0, 0, 0],
        [1, 1 / 4, 0, 0, 0],
        [1, 2 / 4, 1 / 6, 0, 0],
        [1, 3 / 4, 3 / 6, 1 / 4, 0],
        [1, 1, 1, 1, 1],
    ]
)
# value of an inactive pair slot: far below any primitive's, so the pair's max / min structure
# ignores it as it would -inf, without inf arithmetic in products
INACTIVE = -1e300
# ``split_exits`` splits calls of at least this many chain x primitive coefficient builds:
# on a depth-prior three_ledges episode smaller calls (mostly under 0.6 ms) took as long or
# longer split over 2 threads (dispatch, unequal root solving per chain), calls of 2^16 took
# 0.74x (2026-11-28, one-off timing of every call of the episode both ways)
SPLIT_MIN_WORK = 2**15
_POOLS: dict[int, ThreadPoolExecutor] = {}  # ``split_exits``' worker threads, by count
_POOLS_LOCK = threading.Lock()


@numba.njit(cache=True, error_model="numpy")
def _window_roots(coef, solve, span, to_quartic, phi, linear, times, owners):
    """Roots in (ROOT_MIN_TIME, span) of one chain's solved primitives, sorted; their count."""
    n = 0
    x = np.empty(4)
    poly = np.empty(5)
    lo = np.tan(0.5 * (ROOT_MIN_TIME - phi))
    hi = np.tan(0.5 * (span - phi))
    for k in range(coef.shape[1]):
        if not solve[k]:
            continue
        if linear:
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
def pair_value(g, free, plain):
    """A pair's value from its slot values g (6,) (g1..g6, inactive slots INACTIVE), as
    ``PairStructure.pair_values``: > 0 where a free observation's pair is crossed or a
    contact observation's pair unsatisfied; a plain system's one primitive."""
    if plain:
        return g[0]
    gmax = max(max(g[0], g[1]), max(g[2], g[3]))
    gmin = min(min(g[0], g[1]), min(g[2], g[3]))
    return max(-gmax, gmin) if free else max(gmax, max(g[4], g[5]))


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
            if pair_value(g, free, plain) > 0:
                crossed = True
            else:
                unsatisfied = False
            i += 1
        if crossed if (free or plain) else unsatisfied:
            return True
    return False


@numba.njit(cache=True, error_model="numpy")
def _edge_quadratics(y0, yp, out):
    """Trig coefficients k0, k3, k4 (E, 3) into ``out`` of each edge's quad(y0 cos t + yp
    sin t) (``constraints.quad``, y = (c_x, c_y, d_x, d_y)) from y0, yp (E, 4)."""
    for e in range(y0.shape[0]):
        aa = y0[e, 1] * y0[e, 2] - y0[e, 0] * y0[e, 3]
        bb = yp[e, 1] * yp[e, 2] - yp[e, 0] * yp[e, 3]
        ab = 0.5 * (y0[e, 1] * yp[e, 2] + yp[e, 1] * y0[e, 2])
        ab -= 0.5 * (y0[e, 0] * yp[e, 3] + yp[e, 0] * y0[e, 3])
        out[e, 0], out[e, 1], out[e, 2] = 0.5 * (aa + bb), 0.5 * (aa - bb), ab


@numba.njit(cache=True, error_model="numpy")
def _chain_terms(lin0, linp, plain, quad):
    """One chain's per-edge quadratic terms (``quad``, (E, 3); zero for plain systems, whose
    ``psign`` is 0)."""
    if plain:
        quad[:] = 0.0
    else:
        _edge_quadratics(lin0, linp, quad)


@numba.njit(cache=True, error_model="numpy")
def coefficients(lin0, linp, tables, structure):
    """Trig coefficients (C, 5, K) of every primitive along each chain's ellipse, from the
    system's ``ellipse_terms`` (lin0, linp (C, E, J)), ``window_tables`` and
    ``exit_structure`` (the same code as the window search's)."""
    n_chains, n_prims, n_pairs = lin0.shape[0], tables[0].shape[0], structure[0].shape[0]
    out = np.empty((n_chains, 5, n_prims))
    quad, bern = np.empty((lin0.shape[1], 3)), np.empty((5, 5))
    solve, live = np.empty(n_prims, dtype=np.bool_), np.empty(n_pairs, dtype=np.bool_)
    for c in range(n_chains):
        _chain_terms(lin0[c], linp[c], structure[4], quad)
        _chain_window(lin0[c], linp[c], quad, tables, 0.0, bern, structure, out[c], solve, live)
    return out


@numba.njit(cache=True, error_model="numpy")
def bernstein_map(span, out):
    """(5, 5) map into ``out`` from a primitive's trig coefficients (k0..k4) to the Bernstein
    coefficients of its quartic in u = tan(t/2) on [0, tan(span/2)] (span < pi): where they
    share one strict sign, so does the primitive on [0, span] (the polynomial lies in their
    convex hull)."""
    u = np.tan(0.5 * span)
    for i in range(5):
        for j in range(5):
            acc, power = 0.0, 1.0  # substitute u = u_max s, s in [0, 1]
            for m in range(5):
                acc += POWER_TO_BERNSTEIN[i, m] * power * TRIG_TO_POLY[m, j]
                power *= u
            out[i, j] = acc


@numba.njit(cache=True, error_model="numpy")
def _chain_window(lin0, linp, quad, tables, span, bern, structure, coef, solve, live):
    """One chain's trig coefficients (5, K) into ``coef`` (every primitive's, see ``tables``)
    from its ``ellipse_terms`` (lin0, linp (E, J)) and quadratic terms (``_chain_terms``),
    and the primitives worth solving in its window [0, span] (``solve``, K) and the pairs
    worth judging (``live``, P); ``bern`` (5, 5) is scratch.

    A primitive is not solved where it provably keeps a strict sign on the window: first
    |g(0)| > span max|g'| with |g'| <= |k1| + |k2| + 2 (|k3| + |k4|) (cheap, settles most),
    else where its Bernstein coefficients (``bernstein_map``) share one strict sign. A pair
    is live when it can reach a crossing pattern: all its primitives <= 0 (it enters) or,
    for a free observation's pair, all >= 0 (it leaves), counting a primitive that may
    vanish as either; any other pair keeps its pattern through the window, so its roots
    change nothing and they are not solved. Plain systems: the primitives that may vanish
    are live (exact from a feasible start, as in the HMC loop)."""
    weights, lin_edge, g_mean, psign, quad_edge = tables
    pair_prims, _, pair_free, _, plain = structure
    bernstein_map(span, bern)
    for k in range(coef.shape[1]):
        e, qe, s = lin_edge[k], quad_edge[k], psign[k]
        k1 = 0.0
        k2 = 0.0
        for j in range(weights.shape[1]):
            k1 += weights[k, j] * lin0[e, j]
            k2 += weights[k, j] * linp[e, j]
        k0 = g_mean[k] + s * quad[qe, 0]
        k3 = s * quad[qe, 1]
        k4 = s * quad[qe, 2]
        coef[0, k], coef[1, k], coef[2, k], coef[3, k], coef[4, k] = k0, k1, k2, k3, k4
        g0 = k0 + k1 + k3
        if abs(g0) > span * (abs(k1) + abs(k2) + 2.0 * (abs(k3) + abs(k4))):
            solve[k] = False
            continue
        lo, hi = np.inf, -np.inf
        for i in range(5):
            b = bern[i, 0] * k0 + bern[i, 1] * k1 + bern[i, 2] * k2
            b += bern[i, 3] * k3 + bern[i, 4] * k4
            lo, hi = min(lo, b), max(hi, b)
        solve[k] = not (lo > 0 or hi < 0)
    for p in range(pair_prims.shape[0]):
        enter, leave = True, pair_free[p]
        for j in range(pair_prims.shape[1]):
            k = pair_prims[p, j]
            if k >= 0 and not solve[k]:
                g0 = coef[0, k] + coef[1, k] + coef[3, k]
                enter = enter and g0 <= 0
                leave = leave and g0 >= 0
        live[p] = solve[pair_prims[p, 0]] if plain else enter or leave
        if not live[p]:
            for j in range(pair_prims.shape[1]):
                if pair_prims[p, j] >= 0:
                    solve[pair_prims[p, j]] = False


@numba.njit(cache=True, error_model="numpy", nogil=True)
def window_exits(lin0, linp, tables, span, phi, to_quartic, structure):
    """Per chain c, from its ellipse terms (``ellipse_terms`` of the constraint system:
    ``lin0``, ``linp`` (C, E, J)) and the system's ``window_tables``: whether it leaves the
    feasible set in (0, span[c]), when (the root that ends the feasible interval that holds
    t = 0; span where it does not leave), the primitive that root belongs to (-1 if it does
    not leave or is infeasible from the start) and whether the first segment is already
    infeasible (numerical grazing). Each chain's coefficients are built and filtered in one
    pass over the primitives (``_chain_window``) and searched; nothing of size (C, K) is
    stored. Quartics are solved in time shifted by phi, ``to_quartic`` =
    ``intervals.trig_to_quartic(phi)``; ``structure`` is the system's ``exit_structure``:
    per-pair primitives (P, slots; -1 inactive), observation and free flag, per-observation
    contact flag, and whether the system is plain (one primitive per pair and observation,
    all linear: quadratics in u solved instead of quartics)."""
    pair_obs, contact_obs, plain = structure[1], structure[3], structure[4]
    n_chains, n_prims, n_pairs = lin0.shape[0], tables[0].shape[0], pair_obs.shape[0]
    hit = np.zeros(n_chains, dtype=np.bool_)
    stuck = np.zeros(n_chains, dtype=np.bool_)
    dt = span.copy()
    owner = np.full(n_chains, -1)
    coef = np.empty((5, n_prims))
    solve = np.empty(n_prims, dtype=np.bool_)
    live = np.empty(n_pairs, dtype=np.bool_)
    times = np.empty(4 * n_prims)
    owners = np.empty(4 * n_prims, dtype=np.int64)
    live_pairs = np.empty(n_pairs, dtype=np.int64)
    covered = np.zeros(contact_obs.shape[0], dtype=np.bool_)
    g = np.empty(6)
    quad = np.empty((lin0.shape[1], 3))
    bern = np.empty((5, 5))
    for c in range(n_chains):
        _chain_terms(lin0[c], linp[c], plain, quad)
        _chain_window(lin0[c], linp[c], quad, tables, span[c], bern, structure, coef, solve, live)
        n_live = 0
        covered[:] = False
        for p in range(n_pairs):
            if live[p]:
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
        n = _window_roots(coef, solve, span[c], to_quartic, phi, plain, times, owners)
        start = 0.0
        for s in range(n + 1):
            end = times[s] if s < n else span[c]
            mid = 0.5 * (start + end)
            if _segment_violated(coef, mid, live_pairs, n_live, structure, g):
                hit[c], dt[c] = True, start
                if s == 0:
                    stuck[c] = True
                else:
                    owner[c] = owners[s - 1]
                break
            start = end
    return hit, dt, owner, stuck


def split_exits(threads, lin0, linp, tables, span, phi, to_quartic, structure):
    """``window_exits`` with the chains dealt round-robin to ``threads`` parts: one searched
    in the calling thread, the others by the process's pool of ``threads`` - 1 workers
    (``_pool``; the compiled search releases the GIL). Chains are independent, so the results
    are those of one call, bit for bit, in any thread count. One call where a part would get
    fewer than 2 chains or the call is small (chains x primitives < SPLIT_MIN_WORK).

    Decision (not in the paper): round-robin, not contiguous blocks, because a chain's cost
    varies with its bounces and neighbouring chains share seeds; on the calls of a late
    depth-prior three_ledges cycle (16 chains) on 2 cores, contiguous halves took 0.73x of
    one thread, round-robin 0.68x (2026-11-28, medians of 5 timings)."""
    n_chains = lin0.shape[0]
    if threads < 2 or n_chains < 2 * threads or n_chains * tables[0].shape[0] < SPLIT_MIN_WORK:
        return window_exits(lin0, linp, tables, span, phi, to_quartic, structure)
    parts = [np.arange(i, n_chains, threads) for i in range(threads)]
    pool = _pool(threads - 1)
    futures = [
        pool.submit(window_exits, lin0[i], linp[i], tables, span[i], phi, to_quartic, structure)
        for i in parts[1:]
    ]
    first = parts[0]
    results = [
        window_exits(lin0[first], linp[first], tables, span[first], phi, to_quartic, structure)
    ]
    results += [f.result() for f in futures]
    back = np.argsort(np.concatenate(parts))  # the results' rows -> chain order
    return tuple(np.concatenate(pieces)[back] for pieces in zip(*results, strict=True))


def _pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool of ``workers`` threads (made on first use, kept: a pool per HMC call
    would start threads several times per cycle); any thread may submit to it. A forked child
    (``bench docking --workers``) starts without pools: its parent's threads are not in it."""
    with _POOLS_LOCK:
        if workers not in _POOLS:
            _POOLS[workers] = ThreadPoolExecutor(workers, thread_name_prefix="hmc_exit")
        return _POOLS[workers]


def _forget_pools() -> None:
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_forget_pools)


def structure(pair_prims, pair_obs, pair_free, contact_obs, plain: bool) -> tuple:
    """``window_exits``' structure argument (see there), C-contiguous with fixed dtypes, so
    that every system uses the one compiled signature."""
    return (
        np.ascontiguousarray(pair_prims, dtype=np.int64),
        np.ascontiguousarray(pair_obs, dtype=np.int64),
        np.ascontiguousarray(pair_free, dtype=bool),
        np.ascontiguousarray(contact_obs, dtype=bool),
        bool(plain),
    )


def tables(weights, lin_edge, g_mean, psign, quad_edge) -> tuple:
    """``window_exits``' per-system tables: primitive k's trig coefficients along the ellipse
    of chain c are k1 = weights[k] . lin0[c, lin_edge[k]] (k2 the same with linp),
    k0 = g_mean[k] + psign[k] q0, k3 and k4 psign[k] times q3, q4, where (q0, q3, q4) are the
    trig coefficients of quad(lin0[c, e] cos t + linp[c, e] sin t) of edge e = quad_edge[k]
    (``_edge_quadratics``; see ``constraint_systems``); fixed dtypes as ``structure``."""
    return (
        np.ascontiguousarray(weights, dtype=float),
        np.ascontiguousarray(lin_edge, dtype=np.int64),
        np.ascontiguousarray(g_mean, dtype=float),
        np.ascontiguousarray(psign, dtype=float),
        np.ascontiguousarray(quad_edge, dtype=np.int64),
    )


def warm_up() -> None:
    """Compile ``window_exits`` for the HMC loop's argument types (the line scans' kernels:
    ``descent_scan.warm_up``), or load it from the cache
    (``__pycache__`` next to this file, else numba's user-wide cache): the first call after an
    installation compiles for ~10 s, later processes load it in well under a second. The
    inference node calls this at start-up, so that its first posterior is not the one that
    waits."""
    window_exits(
        np.zeros((1, 1, 4)),
        np.zeros((1, 1, 4)),
        tables(np.ones((1, 4)), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1)),
        np.full(1, 0.1),
        0.05,
        trig_to_quartic(0.05),
        structure(np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1), False),
    )
