"""The compiled line scan of the seeding descent (sorted roots, segment judging) against the
numpy interval algebra it replaced."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from constraint_cases import history_system, linear_system

from tactile_dock_ros.core import descent_scan, hmc_exit, intervals, roots, sampling


def test_line_roots_are_each_rows_quadratic_roots_inside_its_window_sorted():
    rng = np.random.default_rng(3)
    coef = rng.standard_normal((6, 300, 3))
    coef[:, ::5, 2] = 0.0  # linear primitives
    coef[:, ::7] = 0.0  # vanishing everywhere: no root
    coef[1] = [1.0, 0.0, 1.0]  # a row without roots (1 + t^2)
    coef[2, ::3] = [1.0, -2.0, 1.0]  # double roots at t = 1, shared by many primitives
    lo, hi = -rng.uniform(0.5, 3, 6), rng.uniform(0.5, 3, 6)
    times, owner = intervals.line_roots(coef, lo, hi)
    each = intervals.quadratic_roots(coef[..., 2], coef[..., 1], coef[..., 0])  # (C, K, 2)
    width = 0
    for c in range(6):
        k, i = np.nonzero((each[c] > lo[c]) & (each[c] < hi[c]))
        order = np.argsort(each[c][k, i], kind="stable")  # ties in primitive order
        width = max(width, k.size)
        assert np.array_equal(times[c, : k.size], each[c][k, i][order])
        assert np.array_equal(owner[c, : k.size], k[order])
        assert np.all(np.isinf(times[c, k.size :])) and np.all(owner[c, k.size :] == -1)
    assert times.shape == (6, width) and np.isinf(times[1]).all()
    assert np.sum(times[2] == 1.0) >= 2 * 100  # each double root counted twice
    row, slot = np.nonzero(owner >= 0)
    q, t = coef[row, owner[row, slot]], times[row, slot]  # each root's own primitive
    scale = np.abs(q).sum(-1) * (1 + t * t)
    assert np.all(np.abs(q[:, 0] + t * (q[:, 1] + t * q[:, 2])) <= 1e-9 * scale)
    empty = roots.line_roots(np.zeros((0, 4, 3)), np.zeros(0), np.zeros(0))
    assert empty[0].shape == (0, 0)


def test_observation_rules_free_any_pair_contact_every_pair_contact_without_pairs_always():
    """obs 0 free (pairs 0, 1), obs 1 contact without pairs, obs 2 contact (pairs 2, 3), obs 3
    free without pairs (never violated); pair k's four slots all hold primitive k."""
    pair_prims = np.array([[k, k, k, k, -1, -1] for k in range(4)])
    structure = hmc_exit.structure(
        pair_prims, [0, 0, 2, 2], [True, True, False, False], [False, True, True, False], False
    )
    # free pair value max(-g, g) = |g| > 0 unless g = 0; contact pair value g
    free_0 = [[0.0, 0.0], [0.0, 0.3]]  # obs 0: no pair crossed / one crossed
    contact = [[0.2, -0.1], [0.2, 0.4]]  # obs 2: one pair satisfied / none
    values = np.array([f + c for f in free_0 for c in contact])  # (4 states, 4 primitives)
    got = descent_scan.violated_counts(values, structure, np.full(4, 9))
    # obs 1 always violated; obs 0 in states 2, 3; obs 2 in states 1, 3
    assert got.tolist() == [1, 2, 2, 3]
    capped = descent_scan.violated_counts(values, structure, np.full(4, 1))
    assert capped.tolist() == [1, 2, 2, 2]  # above the cap: cap + 1
    coef = np.zeros((4, 4, 3))
    coef[..., 0] = values  # constant along the line
    mids = np.zeros((4, 2))
    for obs, expect in [(0, [0, 0, 1, 1]), (1, [1, 1, 1, 1]), (2, [0, 1, 0, 1]), (3, [0] * 4)]:
        got = descent_scan.picked_violated(coef, mids, np.full(4, obs), structure)
        assert got[:, 0].tolist() == [bool(e) for e in expect]


def _linear_case():
    system, _ = linear_system()
    return system, np.random.default_rng(8).standard_normal((32, system.n_dim))


CASES = {
    "notch": lambda: history_system("notch", 3, np.linspace(-0.25, 0.25, 6)),
    "three_ledges": lambda: history_system("three_ledges", 1, np.linspace(-0.3, 0.3, 5)),
    "linear inequalities": _linear_case,
}


@pytest.mark.parametrize("case", list(CASES))
def test_segment_judging_matches_the_numpy_reduction(case):
    """Along random lines: the picked observation at every midpoint and the violated counts at
    candidate points equal ``system.violations`` on the same primitive values, bit for bit."""
    system, z = CASES[case]()
    rng = np.random.default_rng(11)
    d = np.zeros_like(z)
    d[np.arange(len(z)), rng.integers(0, z.shape[1], len(z))] = 1.0  # coordinate lines
    coef = system.line_coefficients(z, d)
    lo, hi = np.full(len(z), -3.0), np.full(len(z), 3.0)
    _, mids = intervals.segment_edges(intervals.line_roots(coef, lo, hi)[0], lo, hi)
    assert mids.shape[1] > 10
    pick = rng.integers(0, system.n_obs, len(z))
    horner = coef[:, None, :, 0] + mids[..., None] * (
        coef[:, None, :, 1] + mids[..., None] * coef[:, None, :, 2]
    )  # (C, S, K)
    want = system.violations(horner)[np.arange(len(z)), :, pick] > 0
    got = descent_scan.picked_violated(coef, mids, pick, system.exit_structure)
    assert np.array_equal(got, want)
    assert 0 < want.mean() < 1  # both verdicts occur

    t = mids[:, :: max(1, mids.shape[1] // 30)]
    powers = np.stack([np.ones_like(t), t, t * t], axis=-1)
    values = np.matmul(powers, coef.swapaxes(1, 2)).reshape(-1, system.n_prims)
    want = np.sum(system.violations(values) > 0, axis=-1)
    assert np.array_equal(
        descent_scan.violated_counts(values, system.exit_structure, np.full(len(want), 10**9)),
        want,
    )
    cap = rng.integers(0, want.max() + 1, len(want))
    capped = descent_scan.violated_counts(values, system.exit_structure, cap)
    assert np.array_equal(capped, np.minimum(want, cap + 1))
    assert np.any(want > cap) and np.any(want <= cap)


@pytest.mark.parametrize("case", ["notch", "three_ledges"])
def test_a_descent_step_never_raises_the_violated_count(case, monkeypatch):
    """The step's rule with the kernels: it moves to a segment with the fewest violations among
    candidates that include the current one, so a row's count never rises (it rose on a third
    of the steps with the candidates' count cap at 0)."""
    system, _ = CASES[case]()
    counts = []
    step = sampling._descent_step

    def recorded(system, z, pick, d, count_now, rng):
        z = step(system, z, pick, d, count_now, rng)
        counts.append((count_now, sampling._violated_count(system, z)))
        return z

    monkeypatch.setattr(sampling, "_descent_step", recorded)
    shape = system.shape
    start = shape.sample_z(np.random.default_rng(2), 8)
    sampling.random_descent(system, start, np.random.default_rng(0), 30)
    before, after = (np.concatenate(c) for c in zip(*counts, strict=True))
    assert len(counts) >= 10
    assert np.all(after <= before)
    assert counts[-1][1].sum() <= counts[0][0].sum() / 2  # and the rows' counts do fall


WARM_UP_COVERS_THE_SAMPLER = """
import json
import numpy as np
from constraint_cases import history_system
from tactile_dock_ros.core import descent_scan, hmc_exit, problems, roots, sampling
kernels = [hmc_exit.window_exits, roots.line_roots, descent_scan.picked_violated,
           descent_scan.violated_counts]
hmc_exit.warm_up()
descent_scan.warm_up()
warmed = [len(k.signatures) for k in kernels]
system, z = history_system("notch", 3, np.linspace(-0.25, 0.25, 6))
start = problems.get("notch").prior.sample_z(np.random.default_rng(2), 8)
assert sampling._violated_count(system, start).min() > 0  # every row takes descent steps
sampling.random_descent(system, start, np.random.default_rng(0), 5)
sampling.hmc_chains(system, z[:8], 2, np.random.default_rng(1))
print(json.dumps({"warmed": warmed, "after": [len(k.signatures) for k in kernels]}))
"""


def test_the_warm_up_compiles_the_signatures_the_sampler_calls():
    """The node's start-up warm-up must compile the very argument types of a descent step and
    an HMC move (dtype, layout, writeability), or the first posterior compiles again (~25 s
    after an install). In a fresh process: no kernel gains a signature after the warm-up."""
    path = os.pathsep.join([str(Path(__file__).parent), *sys.path])
    out = subprocess.run(
        [sys.executable, "-c", WARM_UP_COVERS_THE_SAMPLER],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "PYTHONPATH": path},
    )
    assert out.returncode == 0, out.stderr
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    assert counts["warmed"] == [1, 1, 1, 1] and counts["after"] == counts["warmed"], counts
