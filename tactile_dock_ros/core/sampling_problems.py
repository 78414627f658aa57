"""Histories for the sampling benchmark and tests (paper Fig. 9 and a realistic probe run).

``straight_probe`` is a minimal straight guarded move against a known polyline (no sliding): it
travels from ``start`` along ``direction`` until it first enters the solid and reports the
free part plus a contact segment of length ``resolution`` across the contact, with the
stick/slip status of the edge under a push along the motion (Sec. III-A3). It only builds
benchmark inputs; the full compliant simulator lives in ``core.simulate``.
"""

from __future__ import annotations

import numpy as np

from .history import History, Status
from .problems import Problem

# Fig. 9 problems on the ``sloper`` prior: (free / contact segments, target prior fraction).
# Coordinates were chosen by measuring the prior fraction (benchmark prints the measured value).
FIG9_HISTORIES = {
    "fig9_p1": (
        [((-0.30, 0.45), (-0.30, 0.27)), ((0.0, 0.45), (0.0, 0.10)), ((0.30, 0.45), (0.30, 0.0))],
        [Status.FREE, Status.FREE, Status.FREE],
        0.23,
    ),
}


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

    def cross(p, q):
        return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]

    denom = cross(u, e)  # < 0: the ray enters the solid across the edge (alpha > 0, eq. 6)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross(c - start, e) / denom
        t = cross(c - start, u) / denom
    hit = (denom < 0) & (s > 0) & (s <= reach) & (t >= 0) & (t <= 1)
    if not hit.any():
        return History([start], [start + reach * u], [Status.FREE])
    j = np.flatnonzero(hit)[np.argmin(s[hit])]
    contact = start + s[j] * u
    normal = np.array([e[j, 1], -e[j, 0]]) / np.linalg.norm(e[j])
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
