"""Occlusion basis (Sec. III-A1, Fig. 2): Brownian bridge behind the occluding line, then PCA.

Between the two visible ends ``a`` and ``b`` of a hidden stretch, ``k`` interior vertices at arc
fractions ``s_j = j / (k + 1)`` of the chord are ``a + s_j (b - a) + W_j``, where each coordinate
of ``W`` is an independent Brownian bridge of diffusion ``sigma^2`` per metre of chord:
``cov(W_i, W_j) = sigma^2 L s_i (1 - s_j)`` for ``s_i <= s_j``. The paper's constraint "the
geometry lies on the hidden side of the occluding line" is ``n . W_j >= 0`` with ``n`` the LEFT
normal of the chord ``a -> b`` in terrain order: the chord lies on a line of sight (the far end
was seen past the near end's silhouette), and for both near->far and far->near jumps the
shadow is on the solid side, the left. The constrained bridge is sampled with the exact HMC
below and summarized by its mean and ``columns`` principal components.

Sampler seam: ``sample_truncated_gaussian`` is a small self-contained exact HMC for a whitened
Gaussian under LINEAR constraints (Pakman & Paninski's elliptical trajectories, as in the paper's
Alg. 1 with T = pi/2). It is kept here deliberately instead of calling ``core.sampling``: the
bridge only ever has linear constraints, and this one is vectorized over independent chains.
Any sampler with the same signature can replace it through ``occlusion_columns(sampler=...)``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..core.geometry2d import perp

_TWO_PI = 2.0 * np.pi
_MAX_BOUNCES_PER_TRAJECTORY = 10_000


def sample_truncated_gaussian(
    F: np.ndarray,
    g: np.ndarray,
    start: np.ndarray,
    n_trajectories: int,
    rng: np.random.Generator,
    duration: float = np.pi / 2,
) -> np.ndarray:
    """Exact HMC for ``z ~ N(0, I_d)`` restricted to ``F z + g >= 0``; one chain per start row.

    Each trajectory draws a momentum ``p ~ N(0, I)`` and follows ``z(t) = z0 cos t + p sin t``
    for ``duration``; when a constraint ``F_i z + g_i`` reaches 0 the velocity is reflected about
    that plane and the ellipse restarts from the hit point. Hit times are exact:
    ``F_i z(t) + g_i = u cos(t - phi) + g_i`` leaves the feasible side at
    ``t = phi + arccos(-g_i / u)``.

    Args:
        F: (k, d) constraint rows; g: (k,) offsets.
        start: (C, d) strictly feasible states, one per chain.
        n_trajectories: trajectories per chain; returns only the final states.
        rng: momentum source.
    Returns:
        (C, d) final states (every chain is feasible throughout).
    Raises:
        ValueError for an infeasible start; RuntimeError if a trajectory bounces more than
        10 000 times (degenerate constraints).
    """
    F = np.atleast_2d(np.asarray(F, float))
    g = np.asarray(g, float).reshape(-1)
    z = np.array(start, float, ndmin=2)
    if np.any(z @ F.T + g < 0):
        raise ValueError("HMC start violates the constraints")
    row_norm2 = np.einsum("ij,ij->i", F, F)
    chains = np.arange(len(z))
    for _ in range(n_trajectories):
        p = rng.standard_normal(z.shape)
        remaining = np.full(len(z), duration)
        active = np.ones(len(z), bool)
        for _bounce in range(_MAX_BOUNCES_PER_TRAJECTORY):
            if not active.any():
                break
            idx = chains[active]
            z0, p0 = z[idx], p[idx]
            a, b = z0 @ F.T, p0 @ F.T
            u = np.hypot(a, b)
            can_hit = u > np.abs(g)
            with np.errstate(invalid="ignore", divide="ignore"):
                t_hit = np.arctan2(b, a) + np.arccos(np.clip(-g / u, -1.0, 1.0))
            t_hit = np.mod(t_hit, _TWO_PI)
            t_hit = np.where(can_hit & (t_hit > 1e-10), t_hit, np.inf)
            first = np.argmin(t_hit, axis=1)
            t = np.minimum(t_hit[np.arange(len(idx)), first], remaining[idx])
            cos_t, sin_t = np.cos(t)[:, None], np.sin(t)[:, None]
            z[idx] = z0 * cos_t + p0 * sin_t
            velocity = p0 * cos_t - z0 * sin_t
            bounced = t < remaining[idx]
            Fi = F[first]
            dot = np.einsum("ij,ij->i", Fi, velocity) / row_norm2[first]
            velocity -= np.where(bounced, 2.0 * dot, 0.0)[:, None] * Fi
            p[idx] = velocity
            remaining[idx] -= t
            active[idx] = bounced
        else:
            raise RuntimeError("HMC trajectory exceeded the bounce limit")
    return z


Sampler = Callable[[np.ndarray, np.ndarray, np.ndarray, int, np.random.Generator], np.ndarray]


def arc_fractions(k: int, free_end: bool) -> np.ndarray:
    """(k,) fractions of the chord at which the points sit: interior ``j / (k + 1)`` of a bridge,
    ``j / k`` (the last at the free end) of a Brownian motion."""
    return np.arange(1, k + 1) / (k if free_end else k + 1)


def bridge_covariance(k: int, length_m: float, sigma: float, free_end: bool = False) -> np.ndarray:
    """(k, k) covariance of one coordinate of a Brownian bridge at the k interior points, or
    with ``free_end`` of a Brownian motion from the first end, ``sigma^2 L min(s_i, s_j)``."""
    s = arc_fractions(k, free_end)
    lo, hi = np.minimum.outer(s, s), np.maximum.outer(s, s)
    return sigma**2 * length_m * lo * (1.0 if free_end else 1.0 - hi)


def occlusion_columns(
    a: np.ndarray,
    b: np.ndarray,
    k: int,
    sigma: float,
    columns: int,
    samples: int,
    trajectories: int,
    rng: np.random.Generator,
    sampler: Sampler = sample_truncated_gaussian,
    free_end: bool = False,
    side: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean (k, 2) and PCA basis (2k, r <= columns) of the constrained bridge from a to b.

    ``sigma`` is the diffusion in metres per sqrt(metre); the basis columns are principal
    directions scaled by their standard deviations, so their outer products approximate the
    sample covariance (the variance of the dropped components is lost). ``free_end``: a
    Brownian motion from ``a`` along the chord to ``b`` instead (the hidden tail past a
    silhouette, ``terrain_prior``); ``side = -1`` puts the hidden side right of a -> b.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    chord = b - a
    length = float(np.linalg.norm(chord))
    if k < 1 or length <= 0:
        raise ValueError("a bridge needs k >= 1 interior points between distinct ends")
    normal = side * perp(chord) / length  # left of a -> b: hidden side
    cov = bridge_covariance(k, length, sigma, free_end)
    chol = np.linalg.cholesky(cov)
    F = np.hstack([normal[0] * chol, normal[1] * chol])  # n . W_j on whitened (xi_x, xi_y)
    w0 = 0.5 * np.sqrt(np.diag(cov))  # strictly inside: W_j = w0_j n
    xi0 = np.linalg.solve(chol, w0)
    start = np.tile(np.concatenate([normal[0] * xi0, normal[1] * xi0]), (samples, 1))
    xi = sampler(F, np.zeros(k), start, trajectories, rng)
    W = np.stack([xi[:, :k] @ chol.T, xi[:, k:] @ chol.T], axis=2)  # (S, k, 2)
    s = arc_fractions(k, free_end)[:, None]
    pts = (a + s * chord + W).reshape(samples, 2 * k)
    mean = pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(pts - mean, full_matrices=False)
    r = min(columns, len(sv))
    basis = vt[:r].T * (sv[:r] / np.sqrt(samples - 1))
    return mean.reshape(k, 2), basis
