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

Certificates (2026-11-29): a pair that cannot turn live stays so until its edge has moved
far enough, and most pairs are far. Along a move the state moves on ellipse arcs joined by
reflections; on an arc y0 cos t + yp sin t an edge's end displacements y move at most
|y0| (1 - cos t) + |yp| sin t by time t (``_edge_speeds``, ``_reach``), so per chain and edge
a running sum of that over each window's dt bounds how far the edge has moved (``travel``),
across bounces and moves. When a pair is built, each primitive's clearance (``_clearance``:
how far its edge's ends may move before g = g0 + w.dy + s (quad(y0 + dy) - quad(y0)) can
reach 0) certifies the pair's dead pattern: a free pair stays dead while one primitive > 0
and one < 0 keep their signs, a contact pair while one > 0 does, a plain one while its
primitive does. The pair's certificate is travel + that clearance; a later window skips the
pair while the certificate exceeds its edge's travel by the window's end. A move that is
rejected puts the chain back at its start, so its certificates are dropped. Skipping a pair
that cannot be live changes no exit (see ``_chain_window``): on the calls of two late
depth-prior cycles (three_ledges, 723 calls; sloper, 694) the exits equal those of the search
without certificates bit for bit (root ties keep primitive order), and so do the 960
episodes of the held-out depth-prior run (docs/benchmarks.md). There 82-87 % of the pairs
were skipped per window; the tables are laid out pair by pair (``tables``), as they are read,
and the per-pair helpers are inlined (numba ``inline="always"``: as calls that pass the
table tuples they cost twice as much). The exit search of three_ledges test truth 9's
compliant cycle 11 (episode seed 4; 1,385 calls): 1.84 s -> 0.93 s with certificates alone
(cProfile); its 1,385 recorded calls replayed: 0.87 s (median of 5) with inlining and the
arc bound, against 1.22 s for certificates alone.

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
# a primitive's clearance (``_clearance``, the certificates) gives up this much of |g|: far
# above the rounding of a primitive's value, far below any margin that matters
CERT_SLACK = 1e-12
_POOLS: dict[int, ThreadPoolExecutor] = {}  # ``split_exits``' worker threads, by count
_POOLS_LOCK = threading.Lock()


@numba.njit(cache=True, error_model="numpy")
def _window_roots(coef, solve, n_solve, span, to_quartic, phi, linear, times, owners):
    """Roots in (ROOT_MIN_TIME, span) of one chain's primitives ``solve[:n_solve]``, sorted;
    their count."""
    n = 0
    x = np.empty(4)
    poly = np.empty(5)
    lo = np.tan(0.5 * (ROOT_MIN_TIME - phi))
    hi = np.tan(0.5 * (span - phi))
    for i_solve in range(n_solve):
        k = solve[i_solve]
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
    n_chains, n_prims, n_pairs = lin0.shape[0], tables[3], structure[0].shape[0]
    out = np.empty((n_chains, 5, n_prims))
    quad, bern = np.empty((lin0.shape[1], 3)), np.empty((5, 5))
    found = (
        np.empty(n_prims, dtype=np.int64),
        np.empty(n_pairs, dtype=np.int64),
        np.empty(structure[3].shape[0], dtype=np.bool_),
    )
    travel, speed, safe = np.zeros(lin0.shape[1]), np.zeros((lin0.shape[1], 2)), np.empty(n_pairs)
    for c in range(n_chains):
        safe[:] = -np.inf  # every pair built
        _chain_terms(lin0[c], linp[c], structure[4], quad)
        _edge_speeds(lin0[c], linp[c], speed)
        cert = (travel, speed, safe)
        chain = (lin0[c], linp[c], quad)
        _chain_window(chain, tables, 0.0, bern, structure, out[c], found, cert, True)
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
def _edge_speeds(lin0, linp, out):
    """Per edge, |y0| and |yp| into ``out`` (E, 2): along y0 cos t + yp sin t (until the next
    bounce) the edge's end displacements move at most |y0| (1 - cos t) + |yp| sin t by time
    t (``_reach``: the integral of |y0| sin t + |yp| cos t >= |y'(t)|)."""
    for e in range(lin0.shape[0]):
        a, b = 0.0, 0.0
        for j in range(lin0.shape[1]):
            a += lin0[e, j] * lin0[e, j]
            b += linp[e, j] * linp[e, j]
        out[e, 0], out[e, 1] = np.sqrt(a), np.sqrt(b)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _reach(speed, e, one_minus_cos, sin):
    """How far edge e's ends move at most by the time of ``one_minus_cos``, ``sin``
    (``_edge_speeds``)."""
    return speed[e, 0] * one_minus_cos + speed[e, 1] * sin


@numba.njit(cache=True, error_model="numpy", inline="always")
def _clearance(g0, wnorm, s, y0):
    """How far (Euclidean, in edge coordinates) the edge's ends may move from displacement
    y0 (norm) before a primitive of value g0 can vanish: the root of |w| d + |s| (|y0| d +
    d^2 / 2) = |g0| - CERT_SLACK (|quad(y + v) - quad(y)| <= |y||v| + |v|^2 / 2)."""
    a, b, c = 0.5 * abs(s), wnorm + abs(s) * y0, abs(g0) - CERT_SLACK
    if c <= 0:
        return 0.0
    if a == 0.0:
        return c / b if b > 0 else np.inf
    return 2.0 * c / (b + np.sqrt(b * b + 4.0 * a * c))  # the positive root, stable form


@numba.njit(cache=True, error_model="numpy", inline="always")
def _may_vanish(k0, k1, k2, k3, k4, span, bern):
    """Whether a primitive with trig coefficients k0..k4 may vanish on [0, span]: not where
    |g(0)| > span max|g'| with |g'| <= |k1| + |k2| + 2 (|k3| + |k4|) (cheap, settles most),
    nor where its Bernstein coefficients (``bernstein_map`` into ``bern``) share one strict
    sign."""
    if abs(k0 + k1 + k3) > span * (abs(k1) + abs(k2) + 2.0 * (abs(k3) + abs(k4))):
        return False
    lo, hi = np.inf, -np.inf
    for i in range(5):
        b = bern[i, 0] * k0 + bern[i, 1] * k1 + bern[i, 2] * k2
        b += bern[i, 3] * k3 + bern[i, 4] * k4
        lo, hi = min(lo, b), max(hi, b)
    return not (lo > 0 or hi < 0)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _pair_window(p, e, y0, chain, tables, span, bern, structure, out):
    """Pair p (on edge e, whose ends are displaced by y0, a norm) in one chain's window: its
    primitives' trig coefficients into c (slots, 5) and whether each may vanish into ``may``
    (``_may_vanish``); returns whether the pair is live and its clearance (``_clearance``):
    how far its edge may move before the pair could turn live (0: it may at once).
    ``chain`` = (lin0, linp, quad) as in ``_chain_window``, ``out`` = (c, may)."""
    lin0, linp, quad = chain
    c, may = out
    pair_w, pair_g = tables[0], tables[1]
    pair_prims, _, pair_free, _, plain = structure
    enter, leave = True, pair_free[p]
    above, below = 0.0, 0.0  # the largest clearance of a primitive > 0, < 0
    for j in range(pair_prims.shape[1]):
        if pair_prims[p, j] < 0:
            continue
        s = pair_g[p, j, 1]
        k1 = 0.0
        k2 = 0.0
        for i in range(pair_w.shape[2]):
            k1 += pair_w[p, j, i] * lin0[e, i]
            k2 += pair_w[p, j, i] * linp[e, i]
        k0 = pair_g[p, j, 0] + s * quad[e, 0]
        k3 = s * quad[e, 1]
        k4 = s * quad[e, 2]
        c[j, 0], c[j, 1], c[j, 2], c[j, 3], c[j, 4] = k0, k1, k2, k3, k4
        g0 = k0 + k1 + k3
        if g0 > 0:
            above = max(above, _clearance(g0, pair_g[p, j, 2], s, y0))
        elif g0 < 0:
            below = max(below, _clearance(g0, pair_g[p, j, 2], s, y0))
        may[j] = _may_vanish(k0, k1, k2, k3, k4, span, bern)
        if not may[j]:
            enter = enter and g0 <= 0
            leave = leave and g0 >= 0
    if plain:
        return may[0], max(above, below)
    return enter or leave, min(above, below) if pair_free[p] else above


@numba.njit(cache=True, error_model="numpy")
def _chain_window(chain, tables, span, bern, structure, coef, found, cert, every):
    """One chain's window [0, span]: the trig coefficients (5, K) into ``coef`` of the
    primitives of the pairs it builds (all with ``every``, else those of live pairs), and
    into ``found`` = (solve (K,), live (P,), covered (n_obs,)) the primitives worth solving,
    the pairs worth judging (sorted) and the observations that have one; returns their
    counts. ``chain`` = (lin0, linp, quad): its ``ellipse_terms`` (E, J) each and quadratic
    terms (``_chain_terms``); ``bern`` (5, 5) is scratch.

    A primitive is not solved where it provably keeps a strict sign on the window
    (``_may_vanish``). A pair is live when it can reach a crossing pattern: all its
    primitives <= 0 (it enters) or, for a free observation's pair, all >= 0 (it leaves),
    counting a primitive that may vanish as either; any other pair keeps its pattern through
    the window, so its roots change nothing and they are not solved. Plain systems: the
    primitives that may vanish are live (exact from a feasible start, as in the HMC loop).

    ``cert`` = (travel, speed, safe) (E,), (E, 2), (P,): the chain's path-length bound of each
    edge so far, the edges' speed terms in this window (``_edge_speeds``) and the pairs'
    certificates (``window_exits``). A pair whose certificate exceeds its edge's travel by
    the window's end (travel + ``_reach`` at span) stays dead: it is not built; every other pair is
    built and certified anew."""
    pair_edge = tables[2]
    pair_prims, pair_obs, _, _, _ = structure
    solve, live, covered = found
    travel, speed, safe = cert
    one_minus_cos, sin = 1.0 - np.cos(span), np.sin(span)
    bernstein_map(span, bern)
    slots = pair_prims.shape[1]
    c = np.empty((slots, 5))
    may = np.empty(slots, dtype=np.bool_)
    covered[:] = False
    n_solve, n_live = 0, 0
    for p in range(pair_prims.shape[0]):
        e = pair_edge[p]  # a pair's primitives share its edge (``tables``)
        if safe[p] > travel[e] + _reach(speed, e, one_minus_cos, sin):
            continue
        is_live, clear = _pair_window(
            p, e, speed[e, 0], chain, tables, span, bern, structure, (c, may)
        )
        safe[p] = travel[e] + clear if clear > 0 else -np.inf
        if is_live:
            live[n_live] = p
            n_live += 1
            covered[pair_obs[p]] = True
        if is_live or every:
            for j in range(slots):
                k = pair_prims[p, j]
                if k < 0:
                    continue
                for i in range(5):
                    coef[i, k] = c[j, i]
                if is_live and may[j]:
                    solve[n_solve] = k
                    n_solve += 1
    return n_solve, n_live


@numba.njit(cache=True, error_model="numpy", nogil=True)
def window_exits(lin0, linp, tables, span, phi, to_quartic, structure, certs):
    """Per chain c, from its ellipse terms (``ellipse_terms`` of the constraint system:
    ``lin0``, ``linp`` (C, E, J)) and the system's ``window_tables``: whether it leaves the
    feasible set in (0, span[c]), when (the root that ends the feasible interval that holds
    t = 0; span where it does not leave), the primitive that root belongs to (-1 if it does
    not leave or is infeasible from the start) and whether the first segment is already
    infeasible (numerical grazing). Each chain's coefficients are built and filtered in one
    pass over the pairs its certificates do not skip (``_chain_window``) and searched;
    nothing of size (C, K) is stored. Quartics are solved in time shifted by phi, ``to_quartic`` =
    ``intervals.trig_to_quartic(phi)``; ``structure`` is the system's ``exit_structure``:
    per-pair primitives (P, slots; -1 inactive), observation and free flag, per-observation
    contact flag, and whether the system is plain (one primitive per pair and observation,
    all linear: quadratics in u solved instead of quartics). ``certs`` = (travel (N, E),
    safe (N, P), rows (C,)): the HMC loop's certificate state (``certificates``; chain c's
    row is rows[c]), updated in place: each edge's travel grows by its speed bound times the
    chain's dt, each pair the window builds gets a new certificate (see the module)."""
    pair_obs, contact_obs, plain = structure[1], structure[3], structure[4]
    travel, safe, rows = certs
    n_chains, n_prims, n_pairs = lin0.shape[0], tables[3], pair_obs.shape[0]
    hit = np.zeros(n_chains, dtype=np.bool_)
    stuck = np.zeros(n_chains, dtype=np.bool_)
    dt = span.copy()
    owner = np.full(n_chains, -1)
    coef = np.empty((5, n_prims))
    solve = np.empty(n_prims, dtype=np.int64)
    live_pairs = np.empty(n_pairs, dtype=np.int64)
    covered = np.zeros(contact_obs.shape[0], dtype=np.bool_)
    found = (solve, live_pairs, covered)
    times = np.empty(4 * n_prims)
    owners = np.empty(4 * n_prims, dtype=np.int64)
    g = np.empty(6)
    quad = np.empty((lin0.shape[1], 3))
    speed = np.empty((lin0.shape[1], 2))
    bern = np.empty((5, 5))
    for c in range(n_chains):
        _chain_terms(lin0[c], linp[c], plain, quad)
        _edge_speeds(lin0[c], linp[c], speed)
        cert = (travel[rows[c]], speed, safe[rows[c]])
        chain = (lin0[c], linp[c], quad)
        n_solve, n_live = _chain_window(
            chain, tables, span[c], bern, structure, coef, found, cert, False
        )
        blocked = False  # a contact observation without live pairs: violated throughout
        for o in range(contact_obs.shape[0]):
            if contact_obs[o] and not covered[o]:
                blocked = True
        if blocked:
            hit[c], stuck[c], dt[c] = True, True, 0.0
            continue
        solve[:n_solve].sort()  # ties in time keep primitive order, as in the segment walk
        n = _window_roots(coef, solve, n_solve, span[c], to_quartic, phi, plain, times, owners)
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
        one_minus_cos, sin = 1.0 - np.cos(dt[c]), np.sin(dt[c])
        for e in range(speed.shape[0]):  # the path-length bounds to where the chain stops
            travel[rows[c], e] += _reach(speed, e, one_minus_cos, sin)
    return hit, dt, owner, stuck


def split_exits(threads, lin0, linp, tables, span, phi, to_quartic, structure, certs):
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
    if threads < 2 or n_chains < 2 * threads or n_chains * tables[3] < SPLIT_MIN_WORK:
        return window_exits(lin0, linp, tables, span, phi, to_quartic, structure, certs)
    parts = [np.arange(i, n_chains, threads) for i in range(threads)]
    travel, safe, rows = certs

    def part(i):  # each part updates its chains' rows of ``travel`` and ``safe`` in place
        return (
            *(a[i] for a in (lin0, linp)),
            tables,
            span[i],
            phi,
            to_quartic,
            structure,
            (travel, safe, rows[i]),
        )

    futures = [_pool(threads - 1).submit(window_exits, *part(i)) for i in parts[1:]]
    results = [window_exits(*part(parts[0]))]
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


def tables(weights, lin_edge, g_mean, psign, quad_edge, pair_prims) -> tuple:
    """``window_exits``' per-system tables: primitive k's trig coefficients along the ellipse
    of chain c are k1 = weights[k] . lin0[c, lin_edge[k]] (k2 the same with linp),
    k0 = g_mean[k] + psign[k] q0, k3 and k4 psign[k] times q3, q4, where (q0, q3, q4) are the
    trig coefficients of quad(lin0[c, e] cos t + linp[c, e] sin t) of edge e = quad_edge[k]
    (``_edge_quadratics``; see ``constraint_systems``). Returned per pair and slot of
    ``pair_prims`` (the ``structure``'s), as the window search reads them, pair by pair:
    weights (P, slots, J), (g_mean, psign, |weights|) (P, slots, 3), the pair's edge (P,),
    and the number of primitives K. Fixed dtypes as ``structure``. Raises ValueError unless
    each pair's primitives share one edge, also for their quadratic term (the certificates
    bound the pair by its edge)."""
    weights = np.ascontiguousarray(weights, dtype=float)
    lin_edge = np.ascontiguousarray(lin_edge, dtype=np.int64)
    g_mean = np.ascontiguousarray(g_mean, dtype=float)
    psign = np.ascontiguousarray(psign, dtype=float)
    quad_edge = np.ascontiguousarray(quad_edge, dtype=np.int64)
    prims = np.asarray(pair_prims, dtype=np.int64)
    active = prims >= 0
    at = np.where(active, prims, 0)
    pair_edge = lin_edge[at[np.arange(len(prims)), np.argmax(active, axis=1)]]
    quadratic = active & (psign[at] != 0)
    if np.any(active & (lin_edge[at] != pair_edge[:, None])) or np.any(
        quadratic & (quad_edge[at] != pair_edge[:, None])
    ):
        raise ValueError("the window search needs each pair's primitives on one edge")
    per_prim = np.stack([g_mean, psign, np.sqrt(np.sum(weights * weights, axis=1))], axis=1)
    return (
        np.ascontiguousarray(np.where(active[..., None], weights[at], 0.0)),
        np.ascontiguousarray(np.where(active[..., None], per_prim[at], 0.0)),
        pair_edge,
        len(weights),
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
        tables(np.ones((1, 4)), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), [[0]]),
        np.full(1, 0.1),
        0.05,
        trig_to_quartic(0.05),
        structure(np.zeros((1, 1)), np.zeros(1), np.ones(1), np.zeros(1), False),
        (*certificates(1, 1, 1), np.zeros(1, dtype=np.int64)),
    )


def certificates(n_chains: int, n_edges: int, n_pairs: int) -> tuple:
    """Fresh certificate state for ``window_exits``' ``certs``: per chain the path-length
    bound of each edge (N, E) and each pair's certificate (N, P), none yet."""
    return np.zeros((n_chains, n_edges)), np.full((n_chains, n_pairs), -np.inf)
