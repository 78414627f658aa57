"""Histories for the sampling benchmark and tests (paper Fig. 9 and a realistic probe run).

``straight_probe`` is a minimal straight guarded move against a known polyline (no sliding): it
travels from ``start`` along ``direction`` until it first enters the solid and reports the
free part plus a contact segment of length ``resolution`` across the contact, with the
stick/slip status of the edge under a push along the motion (Sec. III-A3). It only builds
benchmark inputs; the full compliant simulator lives in ``core.simulate``.
"""

from __future__ import annotations

import numpy as np

from . import problems
from .geometry2d import cross, outward_normal
from .history import History, Status
from .problems import Problem


def straight_probe(
    vertices: np.ndarray,
    closed: bool,
    start: np.ndarray,
    direction: np.ndarray,
    friction: float,
    resolution: float,
    reach: float = 10.0,
) -> History:
    """Free + contact observations of one straight guarded move (metres); just the free
    segment up to ``reach`` if nothing is hit."""
    v = np.asarray(vertices, dtype=float)
    start = np.asarray(start, dtype=float)
    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    n = len(v)
    idx = np.arange(n if closed else n - 1)
    c, d = v[idx], v[(idx + 1) % n]
    e = d - c

    denom = cross(u, e)  # < 0: the ray enters the solid across the edge (alpha > 0, eq. 6)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross(c - start, e) / denom
        t = cross(c - start, u) / denom
    hit = (denom < 0) & (s > 0) & (s <= reach) & (t >= 0) & (t <= 1)
    if not hit.any():
        return History([start], [start + reach * u], [Status.FREE])
    j = np.flatnonzero(hit)[np.argmin(s[hit])]
    contact = start + s[j] * u
    normal = outward_normal(e[j]) / np.linalg.norm(e[j])
    tangent = e[j] / np.linalg.norm(e[j])
    push = -u  # the reversed motion must lie in the friction cone to stick (eq. 12)
    vn, ve = push @ normal, push @ tangent
    if abs(ve) <= friction * vn:
        status = Status.STICK
    else:
        status = Status.SLIP_LEFT if ve > 0 else Status.SLIP_RIGHT
    half = 0.5 * resolution
    a = [start, contact - half * u]
    b = [contact - half * u, contact + half * u]
    return History(a, b, [Status.FREE, status])


def probe_history(
    problem: Problem, truth: np.ndarray, xs: np.ndarray, height: float | None = None
) -> History:
    """Vertical downward probes (the load direction) at horizontal positions ``xs`` from
    ``height`` (default: the problem's start height) against the ground truth."""
    y0 = problem.start[1] if height is None else height
    history = History()
    for x in np.asarray(xs, dtype=float):  # one guarded move each; a handful of probes
        probe = straight_probe(
            truth,
            problem.prior.closed,
            (x, y0),
            problem.load,
            problem.friction,
            problem.contact_resolution,
        )
        history = history.extend(probe.a, probe.b, probe.status)
    return history


def _surface_height(vertices: np.ndarray, x: float) -> float:
    """Height of a terrain polyline (vertices run right to left) at horizontal position x."""
    return float(np.interp(x, vertices[::-1, 0], vertices[::-1, 1]))


def fig9_problem(index: int) -> tuple[Problem, History]:
    """Problems 1-3 of Fig. 9 on the ``sloper`` prior: 3, 3 and 5 history segments.

    Built against the prior mean shape; the offsets below were chosen so that the prior
    feasible fractions come out near the paper's 23 %, 2.4 % and 0.2 % (the benchmark measures
    and prints the actual fraction):
    1. three free vertical segments ending 3 cm below the mean surface;
    2. one probe (free + slip contact on the lower hold) at x = 0 and a free segment ending at
       the mean surface at x = 0.25 m;
    3. probes at x = -0.3 and 0.3 m (slip contacts) and a free segment ending 8 mm below the
       surface at x = 0.
    """
    problem = problems.get("sloper")
    truth = problem.prior.mean_vertices
    top = problem.start[1]

    def free(x, depth):
        return History([[x, top]], [[x, _surface_height(truth, x) + depth]], [Status.FREE])

    def joined(*parts):
        out = History()
        for part in parts:
            out = out.extend(part.a, part.b, part.status)
        return out

    if index == 1:
        history = joined(*(free(x, -0.03) for x in (-0.25, 0.0, 0.25)))
    elif index == 2:
        history = joined(probe_history(problem, truth, [0.0]), free(0.25, 0.0))
    elif index == 3:
        history = joined(probe_history(problem, truth, [-0.3, 0.3]), free(0.0, -0.008))
    else:
        raise ValueError(f"Fig. 9 has problems 1, 2 and 3, not {index}")
    return problem, history


def three_ledges_after_probes(
    n_probes: int = 10, seed: int = 0
) -> tuple[Problem, History, np.ndarray]:
    """The ``three_ledges`` prior, a ground truth drawn from it (``seed``) and the history of
    ``n_probes`` vertical probes spread over the terrain's width."""
    problem = problems.get("three_ledges")
    truth = problem.sample_ground_truth(np.random.default_rng(seed))
    history = probe_history(problem, truth, np.linspace(-0.55, 0.25, n_probes))
    return problem, history, truth
