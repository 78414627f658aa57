"""Effective sample size from autocorrelation, and EST = time / ESS (paper Sec. IV-F)."""

from __future__ import annotations

import numpy as np


def effective_sample_size(chains: np.ndarray) -> np.ndarray:
    """Per-coordinate ESS of draws (C chains, N steps, d coordinates) -> (d,).

    Multi-chain autocorrelation (within-chain autocovariance by FFT, combined with the
    between-chain variance as in Gelman et al., BDA3 ch. 11) summed with Geyer's initial
    monotone positive sequence. Coordinates that never vary get ESS = C N. Accepts (N, d) as a
    single chain.
    """
    x = np.asarray(chains, dtype=float)
    if x.ndim == 2:
        x = x[None]
    c, n, d = x.shape
    total = c * n
    if n < 4:
        return np.full(d, float(total))
    centred = x - x.mean(axis=1, keepdims=True)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(centred, n=size, axis=1)
    acov = np.fft.irfft(spec * np.conj(spec), n=size, axis=1)[:, :n] / n  # (C, n, d)
    within = acov[:, 0].mean(axis=0) * n / (n - 1)  # W
    between = n * x.mean(axis=1).var(axis=0, ddof=1) if c > 1 else np.zeros(d)
    var_plus = within * (n - 1) / n + between / n
    varies = var_plus > 1e-300
    safe = np.where(varies, var_plus, 1.0)
    rho = 1.0 - (within - acov.mean(axis=0)) / safe  # (n, d); rho[0] = 1 for one chain
    rho[0] = 1.0
    pairs = rho[: 2 * (n // 2)].reshape(n // 2, 2, d).sum(axis=1)  # Geyer's Gamma_t
    positive = np.cumprod(pairs > 0, axis=0).astype(bool)
    monotone = np.minimum.accumulate(np.where(positive, pairs, 0.0), axis=0)
    tau = -1.0 + 2.0 * monotone.sum(axis=0)
    ess = total / np.maximum(tau, 1.0 / np.log10(max(total, 10)))
    return np.where(varies, ess, float(total))
