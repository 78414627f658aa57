"""The compiled window-exit search of the HMC loop against the numpy interval algebra."""

import multiprocessing
import threading

import numpy as np
import pytest
from constraint_cases import history_system, linear_system
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core import hmc_exit, intervals
from tactile_dock_ros.core.constraint_systems import HistoryConstraints
from tactile_dock_ros.core.constraints import quad

CASES = {
    "notch, live-pair judging": lambda: history_system("notch", 3, np.linspace(-0.25, 0.25, 6)),
    "sloper, small system": lambda: history_system("sloper", 3, [0.0]),
    # the origin is feasible: for linear systems the live set is the primitives that may
    # vanish, exact only from a feasible start, as in the HMC loop
    "linear inequalities": linear_system,
}


def _fresh(system, n_chains: int) -> tuple:
    """``window_exits``' ``certs`` for n chains without certificates yet."""
    travel, safe = hmc_exit.certificates(n_chains, system.n_edges, system.n_pairs)
    return travel, safe, np.arange(n_chains)


@pytest.mark.parametrize("case", list(CASES))
def test_first_exit_matches_judging_every_segment_of_every_primitive(case):
    """Per chain: the compiled search (coefficients from the system's ellipse terms, the
    window filter, live pairs, segments in time order, first infeasible one) gives the same
    exit as solving EVERY primitive with ``intervals.ellipse_roots`` and judging every
    segment midpoint on every primitive: whether, when, on which root, and whether the first
    segment is already infeasible. So the filter drops no root that matters."""
    system, z = CASES[case]()
    rng = np.random.default_rng(5)
    p = rng.standard_normal(z.shape)
    span = rng.uniform(0.05, np.pi / 2, len(z))
    coef = system.ellipse_coefficients(z, p)
    every = np.ones((len(z), system.n_prims), dtype=bool)
    roots, owner = intervals.ellipse_roots(coef, every, system.linear, span)
    edges, mids = intervals.segment_edges(roots, np.zeros(len(z)), span)
    n_real = np.sum(np.isfinite(roots), axis=1) + 1
    bad = np.any(system.violations(np.matmul(intervals.trig_basis(mids), coef)) > 0, axis=-1)
    bad &= np.arange(mids.shape[1]) < n_real[:, None]
    hit, first = bad.any(axis=1), np.argmax(bad, axis=1)
    rows = np.arange(len(z))

    phi = 0.5 * float(span.max())
    got = hmc_exit.window_exits(
        *system.ellipse_terms(z, p), system.window_tables, span, phi,
        intervals.trig_to_quartic(phi), system.exit_structure, _fresh(system, len(z)),
    )  # fmt: skip
    got_hit, got_dt, got_owner, got_stuck = got
    assert 0 < hit.sum() < len(z)  # some ellipses leave the feasible set, some do not
    if isinstance(system, HistoryConstraints):  # infeasible starts and blocked contacts
        assert np.any(got_stuck), "no infeasible start in the batch"
    np.testing.assert_array_equal(got_hit, hit)
    np.testing.assert_allclose(got_dt, np.where(hit, edges[rows, first], span), atol=1e-12)
    np.testing.assert_array_equal(got_stuck, hit & (first == 0))
    leave = hit & (first > 0)
    np.testing.assert_array_equal(got_owner[~leave], -1)
    # the bounce: reflection about the owner's gradient, whose sign does not matter (ties of
    # a primitive and its negative, e.g. a pair's g3 = -g4, may be taken in either order)
    t = got_dt[leave, None]
    z_exit = z[leave] * np.cos(t) + p[leave] * np.sin(t)
    unit = [system.gradient(z_exit, k) for k in (got_owner[leave], owner[leave, first[leave] - 1])]
    unit = [g / np.linalg.norm(g, axis=1, keepdims=True) for g in unit]
    np.testing.assert_allclose(np.abs(np.sum(unit[0] * unit[1], axis=1)), 1.0, atol=1e-9)


def _split_case():
    """The notch case's window-exit arguments on short windows (some chains leave); the
    certificates fresh on each use of the tuple's last item (a callable)."""
    system, z = CASES["notch, live-pair judging"]()
    rng = np.random.default_rng(11)
    p = rng.standard_normal(z.shape)
    span = rng.uniform(0.05, 0.3, len(z))
    phi = 0.5 * float(span.max())
    return (
        *system.ellipse_terms(z, p), system.window_tables, span, phi,
        intervals.trig_to_quartic(phi), system.exit_structure, lambda n: _fresh(system, n),
    )  # fmt: skip


def _chains(args, n):
    """The first n chains of ``_split_case``'s arguments, with fresh certificates."""
    lin0, linp, tables, span, *rest, fresh = args
    return (lin0[:n], linp[:n], tables, span[:n], *rest, fresh(n))


@pytest.mark.parametrize("threads", [2, 3])
def test_exit_search_split_over_threads_gives_the_same_exits(threads, monkeypatch):
    """``split_exits`` deals the chains round-robin to threads: every chain's exit is the one
    the single call finds, in the caller's chain order, and the parts really run on the
    pool's threads (a split that ran everything in the caller would pass the first part).
    Calls too small to be worth it (SPLIT_MIN_WORK) or with under 2 chains a part: one call."""
    args = _split_case()
    n_chains, n_prims = len(args[0]), args[2][3]
    whole = hmc_exit.window_exits(*_chains(args, n_chains))
    assert 0 < whole[0].sum() < n_chains
    seen = []
    search = hmc_exit.window_exits

    def recorded(lin0, *rest):
        seen.append((threading.current_thread().name, len(lin0)))
        return search(lin0, *rest)

    monkeypatch.setattr(hmc_exit, "window_exits", recorded)
    monkeypatch.setattr(hmc_exit, "SPLIT_MIN_WORK", n_chains * n_prims)
    split = hmc_exit.split_exits(threads, *_chains(args, n_chains))
    for got, want in zip(split, whole, strict=True):
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)
    parts = [len(range(i, n_chains, threads)) for i in range(threads)]
    assert sorted(n for _, n in seen) == sorted(parts)
    assert sum(name.startswith("hmc_exit") for name, _ in seen) == threads - 1
    for few in (2 * threads - 1, n_chains - 1):  # too few chains a part; too little work
        seen.clear()
        hmc_exit.split_exits(threads, *_chains(args, few))
        assert [n for _, n in seen] == [few]


def _split_in_child(args, queue):
    queue.put(hmc_exit.split_exits(2, *args))


def test_a_forked_process_splits_on_its_own_threads(monkeypatch):
    """A process forked after its parent split a search (``bench docking --workers``) has none
    of the parent's pool threads: it makes its own instead of waiting for them forever."""
    monkeypatch.setattr(hmc_exit, "SPLIT_MIN_WORK", 0)
    args = _chains(_split_case(), 8)
    whole = hmc_exit.split_exits(2, *args)  # the parent's pool exists now
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    args = _chains(_split_case(), 8)  # fresh certificates: the same call as the parent's
    child = context.Process(target=_split_in_child, args=(args, queue))
    child.start()
    try:
        got = queue.get(timeout=60)
    finally:
        child.join(timeout=10)
        if child.is_alive():
            child.kill()
    for a, b in zip(got, whole, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("case", list(CASES))
def test_window_filter_skips_most_primitives_on_short_windows(case):
    """The filter is what makes the compiled search fast: on a 0.15 rad window most
    primitives are proven to keep their sign and are not solved. Counted through the
    search's own arrays (``_chain_window``), so a filter that keeps everything fails."""
    system, z = CASES[case]()
    p = np.random.default_rng(5).standard_normal(z.shape)
    lin0, linp = system.ellipse_terms(z, p)
    plain = system.exit_structure[-1]
    coef = np.empty((5, system.n_prims))
    found = (
        np.empty(system.n_prims, dtype=np.int64),
        np.empty(system.n_pairs, dtype=np.int64),
        np.empty(len(system.exit_structure[3]), dtype=bool),
    )
    quad, bern = np.empty((lin0.shape[1], 3)), np.empty((5, 5))
    travel, safe, _ = _fresh(system, 1)
    kept = []
    for c in range(len(z)):
        safe[:] = -np.inf
        hmc_exit._chain_terms(lin0[c], linp[c], plain, quad)
        n_solve, _ = hmc_exit._chain_window(
            (lin0[c], linp[c], quad), system.window_tables, 0.15, bern, system.exit_structure,
            coef, found, (travel[0], np.zeros((lin0.shape[1], 2)), safe[0]), True,
        )  # fmt: skip
        np.testing.assert_allclose(coef, system.ellipse_coefficients(z[c : c + 1], p[c : c + 1])[0])
        kept.append(n_solve / system.n_prims)
    assert np.median(kept) < 0.25


@pytest.mark.parametrize("case", list(CASES))
def test_certificates_skip_pairs_and_keep_every_exit(case):
    """Along trajectories of many short windows with bounces (as ``sampling.hmc_chains``
    runs them), the search that keeps its certificates from window to window finds, in
    every window, the exits of a search without any: whether, when, on which primitive; and
    its certificates do cover pairs (most of them, after a few windows). A certificate is
    honoured: every pair certified far beyond any travel leaves nothing to build or judge."""
    system, z = CASES[case]()
    rng = np.random.default_rng(3)
    p = rng.standard_normal(z.shape)
    kept = _fresh(system, len(z))
    span = np.full(len(z), 0.05)
    phi = 0.025
    covered = []
    for _ in range(40):
        lin0, linp = system.ellipse_terms(z, p)
        args = (lin0, linp, system.window_tables, span, phi, intervals.trig_to_quartic(phi))
        reach = np.linalg.norm(lin0, axis=-1) * (1 - np.cos(span[:, None]))
        reach += np.linalg.norm(linp, axis=-1) * np.sin(span[:, None])
        edge = system.window_tables[2]
        travel, safe = kept[0], kept[1]
        covered.append(np.mean(safe > travel[:, edge] + reach[:, edge]))
        got = hmc_exit.window_exits(*args, system.exit_structure, kept)
        want = hmc_exit.window_exits(*args, system.exit_structure, _fresh(system, len(z)))
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
        hit, dt, owner, stuck = want
        t = dt[:, None]
        z, p = z * np.cos(t) + p * np.sin(t), p * np.cos(t) - z * np.sin(t)
        bounce = hit & ~stuck
        if bounce.any():
            g = system.gradient(z[bounce], owner[bounce])
            u = g / np.linalg.norm(g, axis=1, keepdims=True)
            p[bounce] -= 2 * u * np.sum(u * p[bounce], axis=1, keepdims=True)
    assert np.mean(covered[10:]) > 0.5
    everything = (kept[0], np.full_like(kept[1], np.inf), kept[2])
    hit, dt, owner, stuck = hmc_exit.window_exits(*args, system.exit_structure, everything)
    assert np.all(owner == -1) and np.all(dt[~stuck] == span[~stuck])
    if isinstance(system, HistoryConstraints):  # contacts without a live pair: violated
        assert np.all(stuck)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-1, 1).filter(lambda g: abs(g) > 1e-6),
    st.lists(st.floats(-2, 2), min_size=4, max_size=4),
    st.sampled_from([-1.0, 0.0, 1.0]),
    st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    st.floats(0, 1),
)
def test_a_primitive_keeps_its_sign_within_its_clearance(g0, w, s, y0, v, fraction):
    """``_clearance``: moving an edge's ends (y0 -> y0 + v) by less than the clearance of a
    primitive g(y) = g0 + w.(y - y0) + s (quad(y) - quad(y0)) keeps its sign."""
    w, y0, v = np.array(w), np.array(y0), np.array(v)
    reach = hmc_exit._clearance(g0, np.linalg.norm(w), s, np.linalg.norm(y0))
    assert reach >= 0
    if np.linalg.norm(v) == 0 or not np.isfinite(reach):
        return
    step = v / np.linalg.norm(v) * reach * fraction
    moved = g0 + w @ step + s * (quad(y0 + step) - quad(y0))
    assert np.sign(moved) == np.sign(g0)


def test_bernstein_map_proves_a_sign_only_where_there_is_no_root():
    """Where the Bernstein coefficients of a primitive's quartic on [0, t_max] share a strict
    sign (the window filter's second test), the primitive keeps that sign on the whole
    window and has no root there; and the test does prove a sign for many primitives."""
    rng = np.random.default_rng(2)
    coef = rng.normal(size=(50, 5, 40)) * rng.uniform(0, 2, (50, 1, 40))
    coef[:, 0] += rng.normal(0, 3, (50, 40))
    t_max = rng.uniform(0.01, np.pi / 2, 50)
    roots, owner = intervals.ellipse_roots(
        coef, np.ones((50, 40), bool), np.zeros(40, dtype=bool), t_max
    )
    has_root = np.zeros((50, 40), dtype=bool)
    finite = np.isfinite(roots)
    has_root[np.nonzero(finite)[0], owner[finite]] = True
    maps = np.empty((50, 5, 5))
    for c in range(50):
        hmc_exit.bernstein_map(t_max[c], maps[c])
    bern = np.matmul(maps, coef)  # (50, 5, 40)
    proven = (bern.min(axis=1) > 0) | (bern.max(axis=1) < 0)
    assert not np.any(proven & has_root)
    assert proven.mean() > 0.3
    t = t_max[:, None] * np.linspace(0, 1, 33)
    g = np.einsum("cti,cik->ctk", intervals.trig_basis(t), coef)  # (50, 33, 40)
    keeps = np.all(g * np.sign(bern[:, :1]) > 0, axis=1)
    assert np.all(keeps[proven])


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    st.floats(0, np.pi / 2),
)
def test_an_edge_moves_no_further_than_its_reach(y0, yp, t):
    """``_reach``: the path length of y0 cos s + yp sin s over [0, t] is at most
    |y0| (1 - cos t) + |yp| sin t, the bound the certificates' travel adds up."""
    y0, yp = np.array([y0]), np.array([yp])
    speed = np.empty((1, 2))
    hmc_exit._edge_speeds(y0, yp, speed)
    s = np.linspace(0, t, 2001)
    velocity = np.linalg.norm(-np.sin(s)[:, None] * y0 + np.cos(s)[:, None] * yp, axis=1)
    path = np.sum(0.5 * (velocity[1:] + velocity[:-1]) * np.diff(s))
    assert path <= hmc_exit._reach(speed, 0, 1 - np.cos(t), np.sin(t)) + 1e-9
