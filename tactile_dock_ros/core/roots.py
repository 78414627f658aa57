"""Real roots of quadratics and quartics, compiled (numba): the interval algebra's solvers.

One implementation for every caller: the HMC loop's window-exit search (``hmc_exit``, one
polynomial at a time), the batched ``intervals.quadratic_roots`` / ``quartic_roots``
(``ellipse_feasible_set``) and the sorted roots of the line scans (``line_roots``: Gibbs,
seeding descents). Decision: the quartic's closed form
(Ferrari) costs a few dozen flops instead of one LAPACK call per polynomial; where it is
unreliable the companion matrix's eigenvalues are used (``quartic``).
"""

from __future__ import annotations

import numba
import numpy as np

# Roots of a primitive whose imaginary part is below this (relative) are taken as real: a
# spurious root only splits a segment in two, which the midpoint test makes harmless.
IMAG_TOL = 1e-6


@numba.njit(cache=True, error_model="numpy")
def _horner(c, u):
    return (((c[0] * u + c[1]) * u + c[2]) * u + c[3]) * u + c[4]


@numba.njit(cache=True, error_model="numpy")
def _ferrari(c, x):
    """Roots of the quartic c (5,) (scaled, leading coefficient not tiny) into x (4,) (NaN for
    complex pairs); False where the closed form cannot split it (q ~ 0, left to the caller).
    The depressed quartic y^4 + p y^2 + q y + r splits into the two quadratics
    y^2 -+ s y + p/2 + m +- q / (2 s), s = sqrt(2 m), with m > 0 the largest root of the
    resolvent cubic m^3 + p m^2 + (p^2/4 - r) m - q^2/8 (Cardano / Viete, Newton-polished).
    Complex pairs whose imaginary part is below IMAG_TOL (1 + |real part|) count as a double
    real root (as in ``_companion``); every root gets one Newton step on the quartic."""
    a, b, cc, d = c[1] / c[0], c[2] / c[0], c[3] / c[0], c[4] / c[0]
    a2 = a * a
    p = b - 0.375 * a2
    q = cc - 0.5 * a * b + 0.125 * a2 * a
    r = d - 0.25 * a * cc + (b / 16 - 3 * a2 / 256) * a2
    big_p = -p * p / 12 - r
    big_q = (r / 3 - p * p / 108) * p - q * q / 8
    disc = 0.25 * big_q * big_q + big_p**3 / 27
    if disc < 0:  # three real roots of the resolvent: Viete's largest
        root3 = np.sqrt(max(-big_p / 3, 1e-100))
        m = 2 * root3 * np.cos(np.arccos(min(max(-0.5 * big_q / root3**3, -1.0), 1.0)) / 3)
    else:
        w = np.cbrt(-0.5 * big_q - np.copysign(np.sqrt(max(disc, 0.0)), big_q))
        if w == 0:
            w = 1e-300
        m = w - big_p / (3 * w)
    m -= p / 3
    c1 = 0.25 * p * p - r
    df = (3 * m + 2 * p) * m + c1
    step = ((((m + p) * m + c1) * m - 0.125 * q * q) / df) if df != 0 else 0.0
    if abs(step) <= 1e-6 * (1 + abs(m)):
        m -= step
    s = np.sqrt(max(2 * m, 0.0))
    split = s > 1e-7 * (1 + np.sqrt(abs(p)))
    if not split:
        s = 1.0
    for i in range(2):
        sign = -1.0 if i == 0 else 1.0
        lin = s * sign
        const = (0.5 * p + m) - (0.5 * q / s) * sign
        disc2 = lin * lin - 4 * const
        if disc2 >= -4 * IMAG_TOL**2 * (1 + 0.5 * s) ** 2:
            half = -0.5 * (lin + np.copysign(np.sqrt(max(disc2, 0.0)), lin))
            x[i], x[2 + i] = half - 0.25 * a, const / half - 0.25 * a
        else:
            x[i] = x[2 + i] = np.nan
    for i in range(4):
        f = (((c[0] * x[i] + c[1]) * x[i] + c[2]) * x[i] + c[3]) * x[i]
        slope = ((4 * c[0] * x[i] + 3 * c[1]) * x[i] + 2 * c[2]) * x[i] + c[3]
        if abs(slope) > 1e-12:
            x[i] -= (f + c[4]) / slope
    return split


@numba.njit(cache=True, error_model="numpy")
def _companion(c, x):
    """Real roots of the quartic c (5,) into x (4,) by companion-matrix eigenvalues."""
    lead = c[0]
    if abs(lead) < 1e-13:
        lead = -1e-13 if lead < 0 else 1e-13
    comp = np.zeros((4, 4))
    for j in range(4):
        comp[0, j] = -c[j + 1] / lead
    comp[1, 0] = comp[2, 1] = comp[3, 2] = 1.0
    eig = np.linalg.eigvals(comp.astype(np.complex128))
    for i in range(4):
        real = abs(eig[i].imag) <= IMAG_TOL * (1.0 + abs(eig[i].real))
        x[i] = eig[i].real if real else np.nan


@numba.njit(cache=True, error_model="numpy")
def quartic(poly, lo, hi, x):
    """Real roots of poly (5,) (highest degree first) into x (4,), NaN where absent.

    Closed form (``_ferrari``). Polynomials for which it is unreliable are solved by
    companion-matrix eigenvalues instead: a leading coefficient below 1e-3 of the largest
    (roots far out, cancellation), non-finite results, and a count of roots in the window
    (lo, hi) whose parity disagrees with the polynomial's sign change across it (a missed
    crossing; lo = hi = NaN: no window, no such check)."""
    scale = 0.0
    for j in range(5):
        scale = max(scale, abs(poly[j]))
    if scale == 0:
        x[:] = np.nan
        return
    c = poly / scale
    if abs(c[0]) >= 1e-3 and _ferrari(c, x):
        inside = 0
        for i in range(4):
            if np.isinf(x[i]):
                inside = -1  # not finite: the companion matrix decides
                break
            if x[i] > lo and x[i] < hi:
                inside += 1
        crossing = _horner(c, lo) * _horner(c, hi) < 0
        if inside >= 0 and (inside % 2 == 1) == crossing:
            return
    _companion(c, x)


@numba.njit(cache=True, error_model="numpy")
def quadratic(a, b, c, x):
    """Real roots of a x^2 + b x + c into x (2,), NaN where absent; cancellation-free form."""
    scale = max(abs(a), abs(b), abs(c))
    if scale <= 0:
        scale = 1.0
    a, b, c = a / scale, b / scale, c / scale
    disc = b * b - 4 * a * c
    x[0] = x[1] = np.nan
    if a != 0:
        if disc >= 0:
            q = -0.5 * (b + np.copysign(np.sqrt(disc), b))
            x[0], x[1] = q / a, c / q
    elif b != 0:
        x[0] = -c / b
    for i in range(2):
        if not np.isfinite(x[i]):
            x[i] = np.nan


@numba.njit(cache=True, error_model="numpy")
def quadratic_batch(a, b, c):
    """Roots (n, 2) of the quadratics a, b, c (n,) each."""
    out = np.empty((a.shape[0], 2))
    for i in range(a.shape[0]):
        quadratic(a[i], b[i], c[i], out[i])
    return out


@numba.njit(cache=True, error_model="numpy")
def line_roots(coef, lo, hi):
    """Roots strictly inside (lo[c], hi[c]) of each row's quadratics q0 + q1 t + q2 t^2 (coef
    (C, K, 3)), sorted per row (ties in primitive order) and padded with +inf: (C, R), and
    the primitive of each (-1 for padding)."""
    n_rows, n_prims = coef.shape[0], coef.shape[1]
    found = np.empty((n_rows, 2 * n_prims))
    owner = np.empty((n_rows, 2 * n_prims), dtype=np.int64)
    counts = np.zeros(n_rows, dtype=np.int64)
    x = np.empty(2)
    for c in range(n_rows):
        n = 0
        for k in range(n_prims):
            quadratic(coef[c, k, 2], coef[c, k, 1], coef[c, k, 0], x)
            for i in range(2):
                if x[i] > lo[c] and x[i] < hi[c]:  # NaN fails both
                    found[c, n], owner[c, n] = x[i], k
                    n += 1
        counts[c] = n
    times = np.full((n_rows, counts.max() if n_rows else 0), np.inf)
    who = np.full(times.shape, -1, dtype=np.int64)
    for c in range(n_rows):
        order = np.argsort(found[c, : counts[c]], kind="mergesort")
        for i in range(counts[c]):
            times[c, i], who[c, i] = found[c, order[i]], owner[c, order[i]]
    return times, who


@numba.njit(cache=True, error_model="numpy")
def quartic_batch(coef, lo, hi):
    """Roots (n, 4) of the quartics coef (n, 5), windows (lo[i], hi[i]) (see ``quartic``)."""
    out = np.empty((coef.shape[0], 4))
    for i in range(coef.shape[0]):
        quartic(coef[i], lo[i], hi[i], out[i])
    return out
