"""Feasible interval sets along lines and ellipses; Gaussians truncated to them (IV-E, App. A).

Roots of every primitive along the trajectory split the parameter range into segments; the
sign of each primitive is constant inside a segment, so f_H is judged at segment midpoints (the
paper's advice: away from the roots, immune to root error). Combining primitives by the max /
min / negation structure of f_H at those midpoints *is* the interval algebra of Sec. IV-E
(intersection = max, union = min, complement = negation), done for all segments at once.

Arrays carry a leading batch axis C (independent chains). Root arrays are sorted per row and
padded with +inf; ``owner`` gives the primitive each root belongs to (-1 for padding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, ndtri_exp

from . import roots

ROOT_MIN_TIME = 1e-9  # rad: roots of an ellipse this close to its start are the bounce just made


def quadratic_roots(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Real roots (..., 2) of a x^2 + b x + c (NaN where absent); cancellation-free form
    (``roots.quadratic``)."""
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (a, b, c)))
    # fresh writeable contiguous copies: one compiled signature (broadcast views are read-only)
    flat = (np.require(v, float, ["C", "W", "O"]).reshape(-1) for v in (a, b, c))
    return roots.quadratic_batch(*flat).reshape(*a.shape, 2)


def quartic_roots(coef: np.ndarray, window: tuple | None = None) -> np.ndarray:
    """Real roots (n, 4) of polynomials with coefficients (n, 5), highest degree first (NaN
    where absent): ``roots.quartic`` (closed form, companion-matrix fallback) with the window
    (lo, hi) (scalars or (n,)) of its missed-crossing check, if given."""
    coef = np.ascontiguousarray(coef, dtype=float).reshape(-1, 5)
    ends = np.full((2, len(coef)), np.nan)
    if window is not None:
        ends[0], ends[1] = window
    return roots.quartic_batch(coef, ends[0], ends[1])


def trig_basis(t: np.ndarray) -> np.ndarray:
    """(..., 5): 1, cos t, sin t, cos 2t, sin 2t."""
    t = np.asarray(t, dtype=float)
    out = np.empty((*t.shape, 5))
    cos, sin = np.cos(t), np.sin(t)
    out[..., 0], out[..., 1], out[..., 2] = 1.0, cos, sin
    out[..., 3], out[..., 4] = 2 * cos * cos - 1, 2 * sin * cos
    return out


def _sorted_roots(
    row: np.ndarray, roots: np.ndarray, owner: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pad candidate roots into (C, R) rows sorted ascending (inf padding, owner -1).

    row (n,), roots (n, r), owner (n,): candidates of primitive ``owner`` on row ``row``; only
    those strictly inside (lo[row], hi[row]) are kept. Work is linear in the candidates.
    """
    c = len(lo)
    rows = np.repeat(row, roots.shape[1])
    times = roots.reshape(-1)
    owners = np.repeat(owner, roots.shape[1])
    keep = (times > lo[rows]) & (times < hi[rows])  # NaN fails both
    rows, times, owners = rows[keep], times[keep], owners[keep]
    order = np.lexsort((times, rows))
    rows, times, owners = rows[order], times[order], owners[order]
    counts = np.bincount(rows, minlength=c)
    width = int(counts.max(initial=0))
    slot = np.arange(len(rows)) - (np.cumsum(counts) - counts)[rows]
    out = np.full((c, width), np.inf)
    who = np.full((c, width), -1)
    out[rows, slot] = times
    who[rows, slot] = owners
    return out, who


# (1 + u^2)^2 g(t) in ascending powers of u = tan(t/2) from (k0, ..., k4): the quartic of
# ``ellipse_roots`` (and of the HMC window filter's Bernstein test, ``hmc_exit``)
TRIG_TO_POLY = np.array(
    [[1, 1, 0, 1, 0], [0, 0, 2, 0, 4], [2, 0, 0, -6, 0], [0, 0, 2, 0, -4], [1, -1, 0, 1, 0]],
    dtype=float,
)


def trig_to_quartic(phi: float) -> np.ndarray:
    """(5, 5) map from trig coefficients (k0..k4) of g(t) to the quartic (highest degree first)
    (1 + u^2)^2 g(phi + 2 atan u) in u = tan((t - phi)/2)."""
    c1, s1, c2, s2 = np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)
    shift = np.array(
        [
            [1, 0, 0, 0, 0],
            [0, c1, s1, 0, 0],
            [0, -s1, c1, 0, 0],
            [0, 0, 0, c2, s2],
            [0, 0, 0, -s2, c2],
        ]
    )  # coefficients of g(phi + tau) in tau
    return (TRIG_TO_POLY[::-1] @ shift).T


def ellipse_roots(
    coef: np.ndarray,
    solve: np.ndarray,
    linear: np.ndarray,
    t_max: np.ndarray,
    t_min: float = ROOT_MIN_TIME,
) -> tuple[np.ndarray, np.ndarray]:
    """Times in (t_min, t_max[c]) where a primitive along the ellipse vanishes, sorted (C, R).

    coef: trig coefficients (C, 5, K). Only primitives with ``solve`` (C, K) are solved; t_max
    must be < pi. With u = tan(t/2) a linear primitive (k3 = k4 = 0) becomes a quadratic in
    u; systems made only of those solve quadratics. Otherwise every solved primitive is a
    quartic (one batch), in time shifted to the middle of the longest window,
    phi = max(t_max) / 2: u = tan((t - phi)/2) sends the point opposite the windows to
    infinity, so a small leading coefficient (the closed form's weak case) means g is small
    far from every window, not at its start, where the primitive just bounced on vanishes.
    """
    t_max = np.asarray(t_max, dtype=float)
    lo = np.full(len(t_max), t_min)
    ci, ki = np.nonzero(solve)
    if np.all(linear):
        k0, k1, k2 = coef[ci, :3, ki].T
        t = 2 * np.arctan(quadratic_roots(k0 - k1, 2 * k2, k0 + k1))
    else:
        phi = 0.5 * float(t_max.max(initial=0.0))
        poly = coef[ci, :, ki] @ trig_to_quartic(phi)
        window = (np.tan(0.5 * (t_min - phi)), np.tan(0.5 * (t_max[ci] - phi)))
        t = phi + 2 * np.arctan(quartic_roots(poly, window))
    return _sorted_roots(ci, t, ki, lo, t_max)


def line_roots(coef: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters in (lo[c], hi[c]) where a primitive q0 + q1 t + q2 t^2 vanishes, sorted (C, R)
    (compiled, ``roots.line_roots``: a depth-prior descent line crosses ~1000 roots per row)."""
    coef = np.ascontiguousarray(coef, dtype=float)
    c = len(coef)
    lo, hi = (np.array(np.broadcast_to(v, c), dtype=float) for v in (lo, hi))  # writeable
    return roots.line_roots(coef, lo, hi)


def segment_edges(roots: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Segment boundaries (C, R+2) = [lo, roots..., hi] (padding collapsed onto hi) and the
    midpoints (C, R+1)."""
    lo = np.asarray(lo, dtype=float)[:, None]
    hi = np.asarray(hi, dtype=float)[:, None]
    edges = np.concatenate([lo, np.minimum(roots, hi), hi], axis=1)
    return edges, 0.5 * (edges[:, 1:] + edges[:, :-1])


@dataclass(frozen=True)
class IntervalSet:
    """Disjoint closed intervals, (r, 2) rows [start, end] sorted; r = 0 is the empty set."""

    bounds: np.ndarray

    @classmethod
    def from_segments(cls, edges: np.ndarray, ok: np.ndarray) -> IntervalSet:
        """Merge the feasible segments of one row (edges (S+1,), ok (S,)) into intervals."""
        edges, ok = np.asarray(edges, float), np.asarray(ok, bool)
        ok = ok & (edges[1:] > edges[:-1])
        flags = np.concatenate([[False], ok, [False]]).astype(int)
        change = np.diff(flags)
        starts, ends = np.flatnonzero(change == 1), np.flatnonzero(change == -1)
        return cls(np.stack([edges[starts], edges[ends]], axis=1).reshape(-1, 2))

    def contains(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        inside = (t[..., None] >= self.bounds[:, 0]) & (t[..., None] <= self.bounds[:, 1])
        return inside.any(axis=-1)

    @property
    def measure(self) -> float:
        return float(np.sum(self.bounds[:, 1] - self.bounds[:, 0]))


def line_scan(system, z: np.ndarray, d: np.ndarray, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Segments of the lines z + t d, t in [lo, hi] (C rows), for a constraint system (see
    ``core.constraint_systems``): boundaries (C, S+1) and per-segment observation values
    (C, S, k) judged at the midpoints."""
    coef = system.line_coefficients(z, d)
    roots, _ = line_roots(coef, lo, hi)
    edges, mids = segment_edges(roots, lo, hi)
    powers = np.stack([np.ones_like(mids), mids, mids * mids], axis=-1)
    return edges, system.violations(np.matmul(powers, coef.swapaxes(1, 2)))


def line_feasible_set(system, z: np.ndarray, d: np.ndarray, lo: float, hi: float) -> IntervalSet:
    """{t in [lo, hi] : f_H(z + t d) <= 0} for one line (Gibbs ranges, Sec. IV-E)."""
    edges, values = line_scan(system, z[None], d[None], np.array([lo]), np.array([hi]))
    return IntervalSet.from_segments(edges[0], np.all(values[0] <= 0, axis=-1))


def ellipse_feasible_set(system, z0: np.ndarray, p: np.ndarray, t_max: float) -> IntervalSet:
    """{t in [0, t_max] : f_H(z0 cos t + p sin t) <= 0} for one ellipse (HMC ranges, Sec.
    IV-E), every primitive solved (the sampler's filters skip provably irrelevant ones)."""
    coef = system.ellipse_coefficients(z0[None], p[None])
    span = np.array([t_max])
    roots, _ = ellipse_roots(coef, np.ones((1, system.n_prims), dtype=bool), system.linear, span)
    edges, mids = segment_edges(roots, np.zeros(1), span)
    values = system.violations(np.matmul(trig_basis(mids), coef))
    return IntervalSet.from_segments(edges[0], np.all(values[0] <= 0, axis=-1))


def normal_log_mass(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """log P(a <= X <= b) for X ~ N(0, 1), accurate far in either tail (App. A); -inf if b <= a."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    flip = (a + b) > 0  # reflect so the interval's centre is <= 0: log_ndtr is then accurate
    lo, hi = np.where(flip, -b, a), np.where(flip, -a, b)
    lp_lo, lp_hi = log_ndtr(lo), log_ndtr(hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = lp_hi + np.log(-np.expm1(lp_lo - lp_hi))
    return np.where(hi > lo, out, -np.inf)


def sample_truncated_normal(
    edges: np.ndarray,
    ok: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    rng: np.random.Generator,
    log_weight: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One draw per row of N(mean, std^2) restricted to the union of ``ok`` segments (App. A).

    edges (C, S+1), ok (C, S). A segment is chosen with probability proportional to its mass
    (times exp(log_weight) if given), then the draw is an inverse-CDF sample inside it computed
    in log space, safe in the far tails. Returns (draws (C,), found (C,) bool); rows without
    any feasible mass return NaN and False.
    """
    mean = np.asarray(mean, float)[:, None]
    std = np.asarray(std, float)[:, None]
    a, b = (edges[:, :-1] - mean) / std, (edges[:, 1:] - mean) / std
    ok = np.broadcast_to(np.asarray(ok, dtype=bool), a.shape)
    logm = np.full(a.shape, -np.inf)
    logm[ok] = normal_log_mass(a[ok], b[ok])  # only where asked: descents keep <= 33 of ~1000
    if log_weight is not None:
        logm = logm + log_weight
    found = np.isfinite(logm).any(axis=1)
    gumbel = rng.gumbel(size=logm.shape)
    pick = np.argmax(np.where(np.isfinite(logm), logm + gumbel, -np.inf), axis=1)[:, None]
    lo = np.take_along_axis(a, pick, 1)[:, 0]
    hi = np.take_along_axis(b, pick, 1)[:, 0]
    flip = (lo + hi) > 0
    lo_f, hi_f = np.where(flip, -hi, lo), np.where(flip, -lo, hi)
    lp_lo, lp_hi = log_ndtr(lo_f), log_ndtr(hi_f)
    u = rng.random(len(lo))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.exp(lp_lo - lp_hi)
        x = ndtri_exp(lp_hi + np.log(ratio + u * (1.0 - ratio)))
    x = np.clip(np.where(np.isfinite(x), x, 0.5 * (lo_f + hi_f)), lo_f, hi_f)
    x = np.where(flip, -x, x)
    return np.where(found, mean[:, 0] + std[:, 0] * x, np.nan), found
