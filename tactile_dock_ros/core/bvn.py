"""Standard bivariate normal quadrant probabilities, vectorized (paper App. B, eq. 29).

``quadrant(h, k, rho) = P(X <= h, Y <= k)`` for standard normals X, Y with correlation rho.
The method is the Drezner-Wesolowsky formula as refined by Genz (2004, "Numerical computation of
rectangular bivariate and trivariate normal and t probabilities"): for |rho| < 0.925 a
Gauss-Legendre rule (6, 12 or 20 points by |rho|) over the arcsine form of Plackett's identity;
for |rho| >= 0.925 an asymptotic expansion about rho = +-1 plus a 20-point correction integral.
Absolute error is about 1e-15 over the whole range; rho = +-1 are the exact limits.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

_TWO_PI = 2.0 * np.pi
# Limits beyond +-_TAIL are treated as infinite: P(X > 8.5) < 1e-17, so the quadrant then equals
# its univariate limit to within 1e-17 absolute, and the quadrature only sees the rest.
_TAIL = 8.5


def _legendre(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1], shaped (points, 1) to broadcast."""
    x, w = np.polynomial.legendre.leggauss(points)
    return x[:, None], w[:, None]


# |rho| upper bounds of the three quadrature orders (Genz's choice).
_RULES = ((0.3, _legendre(6)), (0.75, _legendre(12)), (0.925, _legendre(20)))
_NEAR_ONE = _legendre(20)


def _upper_moderate(h: np.ndarray, k: np.ndarray, r: np.ndarray, rule) -> np.ndarray:
    """P(X > h, Y > k) for |rho| < 0.925 (1-D arrays): Plackett's identity in arcsine form."""
    x, w = rule
    asr = np.arcsin(r)
    sn = np.sin(asr * (x + 1.0) / 2.0)  # (points, count)
    hk, hs = h * k, (h * h + k * k) / 2.0
    integral = np.sum(w * np.exp((sn * hk - hs) / (1.0 - sn * sn)), axis=0)
    return integral * asr / (4.0 * np.pi) + ndtr(-h) * ndtr(-k)


def _upper_strong(h: np.ndarray, k: np.ndarray, r: np.ndarray) -> np.ndarray:
    """P(X > h, Y > k) for 0.925 <= |rho| <= 1 (1-D arrays): Genz's expansion about |rho| = 1."""
    negative = r < 0
    k = np.where(negative, -k, k)
    hk = h * k
    out = np.zeros_like(h)
    inner = np.abs(r) < 1.0
    if np.any(inner):
        hi, ki, hki, ri = h[inner], k[inner], hk[inner], np.abs(r[inner])
        a_sq = (1.0 - ri) * (1.0 + ri)
        a = np.sqrt(a_sq)
        b_sq = (hi - ki) ** 2
        c = (4.0 - hki) / 8.0
        d = (12.0 - hki) / 16.0
        val = (
            a
            * np.exp(-(b_sq / a_sq + hki) / 2.0)
            * (1.0 - c * (b_sq - a_sq) * (1.0 - d * b_sq / 5.0) / 3.0 + c * d * a_sq * a_sq / 5.0)
        )
        b = np.sqrt(b_sq)
        tail = (  # dropped below hk = -160; the clip only keeps exp finite there
            np.exp(-np.maximum(hki, -160.0) / 2.0)
            * np.sqrt(_TWO_PI)
            * ndtr(-b / a)
            * b
            * (1.0 - c * b_sq * (1.0 - d * b_sq / 5.0) / 3.0)
        )
        val -= np.where(hki > -160.0, tail, 0.0)
        x, w = _NEAR_ONE
        half = a / 2.0
        xs = (half * (x + 1.0)) ** 2  # (points, count)
        rs = np.sqrt(1.0 - xs)
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            expo = -(b_sq / xs + hki) / 2.0
            term = np.exp(-b_sq / (2.0 * xs) - hki / (1.0 + rs)) / rs - np.exp(expo) * (
                1.0 + c * xs * (1.0 + d * xs)
            )
        term = np.where(expo > -100.0, term, 0.0)
        val += half * np.sum(w * term, axis=0)
        out[inner] = -val / _TWO_PI
    # rho > 0: add P(X > max(h, k)); rho < 0: reflect, P(X > h, X < -k) when the interval is open.
    pos = ~negative
    out[pos] += ndtr(-np.maximum(h[pos], k[pos]))
    neg = negative
    hn, kn = h[neg], k[neg]
    gap = np.where(
        hn < 0.0, ndtr(kn) - ndtr(hn), ndtr(-hn) - ndtr(-kn)
    )  # P(h < X < k), accurate in both tails
    out[neg] = -out[neg] + np.where(kn > hn, gap, 0.0)
    return out


def quadrant(h, k, rho) -> np.ndarray:
    """``P(X <= h, Y <= k)`` for standard bivariate normals with correlation ``rho`` (eq. 29).

    Broadcasts its arguments. ``h``, ``k`` may be +-inf (the univariate limits); ``rho`` must lie
    in [-1, 1] (+-1 give the degenerate limits). NaN anywhere raises ValueError.
    """
    h, k, rho = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (h, k, rho)))
    if np.isnan(h).any() or np.isnan(k).any() or np.isnan(rho).any():
        raise ValueError("bvn.quadrant: NaN in h, k or rho")
    if np.any(np.abs(rho) > 1.0):
        raise ValueError("bvn.quadrant: rho must lie in [-1, 1]")
    shape = h.shape
    # Upper orthant of (-X, -Y): P(X <= h, Y <= k) = P(-X >= -h, -Y >= -k), same correlation.
    uh, uk, r = -h.ravel(), -k.ravel(), rho.ravel()
    out = np.empty(uh.shape)
    # Infinite (or beyond _TAIL) limits reduce to one dimension; clip them out of the quadrature.
    inf_h, inf_k = np.abs(uh) > _TAIL, np.abs(uk) > _TAIL
    finite = ~(inf_h | inf_k)
    out[inf_h] = np.where(uh[inf_h] > 0, 0.0, ndtr(-uk[inf_h]))
    only_k = inf_k & ~inf_h
    out[only_k] = np.where(uk[only_k] > 0, 0.0, ndtr(-uh[only_k]))
    absr = np.abs(r)
    lower = 0.0
    for upper, rule in _RULES:
        sel = finite & (absr >= lower) & (absr < upper)
        if np.any(sel):
            out[sel] = _upper_moderate(uh[sel], uk[sel], r[sel], rule)
        lower = upper
    sel = finite & (absr >= lower)
    if np.any(sel):
        out[sel] = _upper_strong(uh[sel], uk[sel], r[sel])
    return np.clip(out, 0.0, 1.0).reshape(shape)
