"""Empirical Bayes for the surface model (``surface.py``, step 2) from depth scans alone.

Data: per visible run of a scan's slice, the measured second differences ``c`` along the vertex
normals (``surface.normal_noise``; ``h`` times the measured turn at each inner vertex) and the
vertex measurement variances ``S`` the smoother uses (median-of-N pixels, depth resolution,
incidence). Rows next to a run end at a depth jump are dropped: the smoother puts no turn prior
there (an occluder's corner may turn any way), so they carry nothing about the hyperparameters.

Generative model (fitted): ``c = t + D2 e`` with measurement noise ``e ~ N(0, kappa^2 S)`` at the
vertices (so ``D2 e ~ N(0, kappa^2 D2 S D2^T)``, a band of half-width 2) and true turns ``t_i``
independent across vertices, each a face turn with probability ``1 - pi``, ``N(0, (h sigma)^2)``,
or a corner with probability ``pi``, ``N(0, (h tau)^2)`` with ``tau > sigma``. Parameters
``theta = (sigma, pi, tau, kappa)``; ``kappa`` scales the smoother's measurement noise.

Why not the smoother's own Gaussian ``N(c; 0, D2 S D2^T + Q)`` as the evidence: its corner rule
makes ``Q`` depend on ``c`` itself (``q_i = (h bend)^2 + e_i^2`` with ``e_i`` the excess of
``|c_i|`` over ``corner_threshold`` noise stds), so it is no density of ``c``, and maximizing it
over the threshold lets the vertices explain themselves: on the 210 train scans of
``tools.fit_surface_prior --render-training 210 --seed 0`` its maximum over a grid lies at the
smallest bend tried (0.001 rad) and a threshold of 0.5 noise stds, which calls about 60 % of
the face vertices corners (``smoother_log_evidence`` computes it exactly, full banded
covariance; the tool reports it, nothing maximizes it).
The spike-and-slab above is the proper model the rule approximates.

Fit: the exact evidence of the spike-and-slab sums over 2^m corner sets of a run; instead
``theta`` maximizes the pairwise composite likelihood, the sum over every pair of rows of a run
within the noise band (lags 1 and 2, the only non-zero correlations of ``D2 S D2^T``) of their
exact bivariate mixture density (``pairwise_log_likelihood``; rows without a partner add their
marginal). Each pair's marginal is exact, so the estimate is consistent; keeping the pairs
(rather than single rows) is what tells ``kappa`` from ``sigma``: the noise of neighbouring rows
is correlated (about -2/3 at lag 1), turns are not. L-BFGS-B on ``(log sigma, logit pi,
log(tau / sigma - 1), log kappa)`` from a few starts. ``fit_mixture`` recovers ``theta`` from data
drawn from the model (``sample_runs``; test/test_surface_fit.py).

Decision, the smoother's two knobs (what ``tools.fit_surface_prior`` writes): the smoother is a
Gaussian with a detected-corner rule and cannot be the mixture, so ``bend_sigma_rad`` and
``corner_threshold`` are the values whose per-vertex Gaussian posterior of the true turn
(prior ``q_i`` of the rule, the smoother's own noise ``B_ii = (D2 S D2^T)_ii``, no ``kappa``)
is closest to the fitted mixture's posterior of that turn: they maximize the expected log
score ``E[log N(t_i; m_i, V_i)]`` over the training rows, the expectation under the mixture's
posterior given ``c_i`` (the KL projection onto the smoother's family; ``project_to_smoother``).
Single rows, not runs: the smoother's neighbours and the sagitta floor are left out of the
projection. Without corners (``pi = 0``) and ``kappa = 1`` it returns the true ``sigma`` and the
threshold's upper bound (no corners).

Fixed, not fitted: ``kappa`` is a nuisance parameter (fitted so that a misjudged pixel noise
is not read as bend; the config has no noise scale and the projection uses the smoother's own
noise, so its effect lands in the two knobs); ``quantization_m`` (the image's depth step,
known); ``variance_kept`` (a compression tolerance, no model parameter); ``depth_model``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special

from .config import DepthNoise, Extrinsic, SurfaceParams
from .slicing import TerrainSlice
from .surface import normal_noise, ray_sigma, run_inputs

BEND_BOUNDS = (1e-3, 1.0)  # rad per vertex
THRESHOLD_BOUNDS = (0.0, 8.0)  # noise stds; the upper bound: practically no corners
FRACTION_BOUNDS = (1e-4, 0.5)  # corner probability pi
RATIO_BOUNDS = (1.5, 2000.0)  # tau / sigma
NOISE_SCALE_BOUNDS = (0.1, 10.0)
_LOG_2PI = float(np.log(2 * np.pi))


@dataclass(frozen=True)
class Run:
    """One visible run's data: what the smoother sees of it."""

    s2: np.ndarray  # (r,) measurement variance of each vertex along its normal, m^2
    c: np.ndarray  # (r - 2,) measured second differences along the normals, m
    keep: np.ndarray  # (r - 2,) bool: rows with a turn prior (not next to a jump end)
    spacing_m: float


def slice_runs(
    terrain: TerrainSlice, extrinsic: Extrinsic, noise: DepthNoise, surface: SurfaceParams
) -> list[Run]:
    """The runs of a slice with at least one kept row, under the correlated model's noise."""
    surface = dataclasses.replace(surface, depth_model="correlated")
    sigma = ray_sigma(terrain, extrinsic, noise, surface)
    runs = []
    for lo, hi, rays, jump_ends in run_inputs(terrain):
        if hi - lo < 3:
            continue
        _, s2, c = normal_noise(
            terrain.vertices[lo:hi], rays, sigma[lo:hi], terrain.spacing_m, jump_ends
        )
        keep = np.ones(len(c), bool)
        keep[0] &= not jump_ends[0]
        keep[-1] &= not jump_ends[1]
        if keep.any():
            runs.append(Run(s2, c, keep, float(terrain.spacing_m)))
    return runs


def band(s2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Diagonal (m,), lag-1 (m-1,) and lag-2 (m-2,) bands of ``D2 diag(s2) D2^T``."""
    return (
        s2[:-2] + 4 * s2[1:-1] + s2[2:],
        -2 * s2[1:-2] - 2 * s2[2:-1],
        s2[2:-2],
    )


@dataclass(frozen=True)
class Differences:
    """The kept rows of many runs, flattened, and their pairs within the noise band."""

    c: np.ndarray  # (N,) m
    noise: np.ndarray  # (N,) (D2 S D2^T)_ii, m^2
    spacing: np.ndarray  # (N,) h, m
    first: np.ndarray  # (P,) row index of each pair
    second: np.ndarray  # (P,) its partner, 1 or 2 rows later in the same run
    pair_noise: np.ndarray  # (P,) their noise covariance, m^2
    single: np.ndarray  # (N,) bool: rows in no pair (their marginal counts)

    @classmethod
    def from_runs(cls, runs: list[Run]) -> Differences:
        if not runs:
            raise ValueError("no runs to fit")
        diag, lag1, lag2 = zip(*(band(r.s2) for r in runs), strict=True)
        lengths = np.array([len(r.c) for r in runs])
        run_id = np.repeat(np.arange(len(runs)), lengths)
        keep = np.concatenate([r.keep for r in runs])
        index = np.cumsum(keep) - 1  # position among the kept rows
        first, second, cov = [], [], []
        for lag, values in ((1, lag1), (2, lag2)):
            # a run's band of this lag, padded with one dummy per run so rows line up
            flat = np.concatenate(
                [np.r_[v, np.zeros(lag)][: len(r.c)] for v, r in zip(values, runs, strict=True)]
            )
            i = np.arange(len(keep) - lag)
            ok = (run_id[i] == run_id[i + lag]) & keep[i] & keep[i + lag]
            first.append(index[i[ok]])
            second.append(index[i[ok] + lag])
            cov.append(flat[i[ok]])
        first, second = np.concatenate(first), np.concatenate(second)
        single = np.ones(int(keep.sum()), bool)
        single[first] = single[second] = False
        return cls(
            c=np.concatenate([r.c for r in runs])[keep],
            noise=np.concatenate(diag)[keep],
            spacing=np.concatenate([np.full(len(r.c), r.spacing_m) for r in runs])[keep],
            first=first,
            second=second,
            pair_noise=np.concatenate(cov),
            single=single,
        )


@dataclass(frozen=True)
class Mixture:
    """theta of the generative model (module docstring)."""

    bend_sigma_rad: float  # sigma: face turn std per vertex
    corner_fraction: float  # pi
    corner_sigma_rad: float  # tau: corner turn std
    noise_scale: float  # kappa

    def vector(self) -> np.ndarray:
        ratio = self.corner_sigma_rad / self.bend_sigma_rad
        return np.array(
            [
                np.log(self.bend_sigma_rad),
                special.logit(self.corner_fraction),
                np.log(ratio - 1.0),
                np.log(self.noise_scale),
            ]
        )

    @classmethod
    def from_vector(cls, x) -> Mixture:
        bend = float(np.exp(x[0]))
        return cls(
            bend, float(special.expit(x[1])), bend * (1 + float(np.exp(x[2]))), float(np.exp(x[3]))
        )


def _component_variances(d: Differences, m: Mixture) -> np.ndarray:
    """(2, N) marginal variance of each row as a face (0) or a corner (1)."""
    turn = np.stack([(d.spacing * m.bend_sigma_rad) ** 2, (d.spacing * m.corner_sigma_rad) ** 2])
    return m.noise_scale**2 * d.noise + turn


def pairwise_log_likelihood(d: Differences, m: Mixture) -> float:
    """Composite log likelihood: exact bivariate mixture densities of the pairs, marginals of
    the rows without a partner (module docstring)."""
    var = _component_variances(d, m)
    log_w = np.log([1.0 - m.corner_fraction, m.corner_fraction])
    ci, cj, cov = d.c[d.first], d.c[d.second], m.noise_scale**2 * d.pair_noise
    terms = []
    for zi in (0, 1):
        for zj in (0, 1):
            vi, vj = var[zi, d.first], var[zj, d.second]
            det = vi * vj - cov**2
            quad = (vj * ci**2 - 2 * cov * ci * cj + vi * cj**2) / det
            terms.append(log_w[zi] + log_w[zj] - _LOG_2PI - 0.5 * np.log(det) - 0.5 * quad)
    total = special.logsumexp(np.stack(terms), axis=0).sum()
    c, v = d.c[d.single], var[:, d.single]
    single = log_w[:, None] - 0.5 * (_LOG_2PI + np.log(v) + c**2 / v)
    return float(total + special.logsumexp(single, axis=0).sum())


@dataclass(frozen=True)
class MixtureFit:
    mixture: Mixture
    log_likelihood: float  # pairwise composite
    pairs: int
    at_bounds: tuple[str, ...]  # parameters that ended on a bound


def fit_mixture(d: Differences) -> MixtureFit:
    """Maximize ``pairwise_log_likelihood`` over theta (L-BFGS-B, several starts)."""
    bounds = [
        np.log(BEND_BOUNDS),
        special.logit(FRACTION_BOUNDS),
        np.log(np.subtract(RATIO_BOUNDS, 1.0)),
        np.log(NOISE_SCALE_BOUNDS),
    ]
    scale = max(len(d.first), 1)

    def objective(x):
        return -pairwise_log_likelihood(d, Mixture.from_vector(x)) / scale

    best = None
    for bend in (0.01, 0.1):
        for fraction in (0.02, 0.2):
            x0 = Mixture(bend, fraction, 0.5, 1.0).vector()
            res = optimize.minimize(objective, x0, method="L-BFGS-B", bounds=bounds)
            if best is None or res.fun < best.fun:
                best = res
    names = ("bend_sigma_rad", "corner_fraction", "corner_ratio", "noise_scale")
    lows, highs = np.array(bounds).T
    edge = np.isclose(best.x, lows, atol=1e-3) | np.isclose(best.x, highs, atol=1e-3)
    return MixtureFit(
        Mixture.from_vector(best.x),
        -best.fun * scale,
        len(d.first),
        tuple(n for n, e in zip(names, edge, strict=True) if e),
    )


def turn_posterior(d: Differences, m: Mixture) -> tuple[np.ndarray, np.ndarray]:
    """(N,) mean and variance of each row's true turn ``t_i`` given ``c_i`` alone, under m."""
    noise = m.noise_scale**2 * d.noise
    var = _component_variances(d, m)
    prior = var - noise
    log_r = np.log([1.0 - m.corner_fraction, m.corner_fraction])[:, None]
    log_r = log_r - 0.5 * (np.log(var) + d.c**2 / var)
    r = np.exp(log_r - special.logsumexp(log_r, axis=0))
    mean_k, var_k = prior * d.c / var, prior * noise / var
    mean = np.sum(r * mean_k, axis=0)
    return mean, np.sum(r * (var_k + mean_k**2), axis=0) - mean**2


def smoother_turn_variance(c, noise, spacing, bend_sigma_rad, corner_threshold):
    """The smoother's prior variance of each turn: ``(h bend)^2 + e^2`` (``surface.smooth_run``)."""
    excess = np.maximum(np.abs(c) - corner_threshold * np.sqrt(noise), 0.0)
    return (spacing * bend_sigma_rad) ** 2 + excess**2


def expected_log_score(
    d: Differences, m: Mixture, bend_sigma_rad, corner_threshold, posterior=None
) -> np.ndarray:
    """Mean over rows of ``E[log N(t_i; m_i, V_i)]``: the smoother's posterior of the turn
    (mean m_i, variance V_i; its own noise) scored against the mixture's posterior of it.
    Broadcasts over arrays of ``bend_sigma_rad`` / ``corner_threshold`` (shape (...,))."""
    mean, var = turn_posterior(d, m) if posterior is None else posterior
    bend = np.asarray(bend_sigma_rad, float)[..., None]
    threshold = np.asarray(corner_threshold, float)[..., None]
    q = smoother_turn_variance(d.c, d.noise, d.spacing, bend, threshold)
    m_s, v_s = q * d.c / (q + d.noise), q * d.noise / (q + d.noise)
    score = -0.5 * (_LOG_2PI + np.log(v_s) + (var + (mean - m_s) ** 2) / v_s)
    return score.mean(axis=-1)


def project_to_smoother(d: Differences, m: Mixture) -> tuple[float, float, float]:
    """(bend_sigma_rad, corner_threshold, expected log score per row) maximizing
    ``expected_log_score`` within ``BEND_BOUNDS`` x ``THRESHOLD_BOUNDS``: a grid, then
    Nelder-Mead from its best point."""
    posterior = turn_posterior(d, m)
    bends = np.geomspace(*BEND_BOUNDS, 31)
    thresholds = np.linspace(*THRESHOLD_BOUNDS, 33)
    grid = np.array(
        [expected_log_score(d, m, bends, t, posterior) for t in thresholds]
    )  # (thresholds, bends)
    ti, bi = np.unravel_index(np.argmax(grid), grid.shape)

    def objective(x):
        return -float(expected_log_score(d, m, np.exp(x[0]), x[1], posterior))

    res = optimize.minimize(
        objective,
        [np.log(bends[bi]), thresholds[ti]],
        method="Nelder-Mead",
        bounds=[np.log(BEND_BOUNDS), THRESHOLD_BOUNDS],
        options={"xatol": 1e-4, "fatol": 1e-7},
    )
    return float(np.exp(res.x[0])), float(res.x[1]), -float(res.fun)


def smoother_log_evidence(
    runs: list[Run], bend_sigma_rad: float, corner_threshold: float, noise_scale: float = 1.0
) -> float:
    """Sum over runs of ``log N(c; 0, kappa^2 D2 S D2^T + Q)`` over the kept rows, with the
    smoother's plug-in ``Q`` (depends on c: no density of c, see module docstring). Exact, all
    runs at once: covariances padded to a common size with identity rows (c = 0 there)."""
    size = max(int(r.keep.sum()) for r in runs)
    cov = np.tile(np.eye(size), (len(runs), 1, 1))
    vec = np.zeros((len(runs), size))
    for k, r in enumerate(runs):
        diag, lag1, lag2 = band(r.s2)
        B = (
            np.diag(diag)
            + np.diag(lag1, 1)
            + np.diag(lag1, -1)
            + np.diag(lag2, 2)
            + np.diag(lag2, -2)
        )
        B = B[np.ix_(r.keep, r.keep)]
        c, noise = r.c[r.keep], diag[r.keep]
        q = smoother_turn_variance(c, noise, r.spacing_m, bend_sigma_rad, corner_threshold)
        m = len(c)
        cov[k, :m, :m] = noise_scale**2 * B + np.diag(q)
        vec[k, :m] = c
    chol = np.linalg.cholesky(cov)
    white = np.linalg.solve(chol, vec[..., None])[..., 0]
    rows = sum(int(r.keep.sum()) for r in runs)
    logdet = 2 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum()
    return float(-0.5 * (np.sum(white**2) + logdet + rows * _LOG_2PI))


def sample_runs(runs: list[Run], m: Mixture, rng: np.random.Generator) -> list[Run]:
    """Runs with the same noise, spacing and kept rows, their c drawn from the model m."""
    out = []
    for r in runs:
        corner = rng.random(len(r.c)) < m.corner_fraction
        turn = r.spacing_m * np.where(corner, m.corner_sigma_rad, m.bend_sigma_rad)
        e = m.noise_scale * np.sqrt(r.s2) * rng.standard_normal(len(r.s2))
        c = turn * rng.standard_normal(len(r.c)) + e[:-2] - 2 * e[1:-1] + e[2:]
        out.append(dataclasses.replace(r, c=c))
    return out


@dataclass(frozen=True)
class SurfaceFit:
    """Result of ``fit_surface``."""

    bend_sigma_rad: float
    corner_threshold: float
    mixture: MixtureFit
    rows: int
    runs: int
    score: dict  # expected log score per row: {"before": ..., "after": ...}
    smoother_evidence: dict  # smoother_log_evidence: {"before": ..., "after": ...}
    before: SurfaceParams

    def surface(self) -> SurfaceParams:
        return dataclasses.replace(
            self.before,
            bend_sigma_rad=self.bend_sigma_rad,
            corner_threshold=self.corner_threshold,
        )

    def to_dict(self) -> dict:
        mix = self.mixture
        return {
            "fitted": {
                "bend_sigma_rad": self.bend_sigma_rad,
                "corner_threshold": self.corner_threshold,
            },
            "before": {
                "bend_sigma_rad": self.before.bend_sigma_rad,
                "corner_threshold": self.before.corner_threshold,
            },
            "rows": self.rows,
            "runs": self.runs,
            "mixture": {
                **dataclasses.asdict(mix.mixture),
                "pairwise_log_likelihood": mix.log_likelihood,
                "pairs": mix.pairs,
                "at_bounds": list(mix.at_bounds),
            },
            "expected_log_score_per_row": self.score,
            "smoother_log_evidence": self.smoother_evidence,
        }


def fit_surface(runs: list[Run], before: SurfaceParams) -> SurfaceFit:
    """Fit the mixture on the runs, project it onto the smoother's two knobs; scores of the
    ``before`` values (the config's) and of the fitted ones."""
    d = Differences.from_runs(runs)
    mix = fit_mixture(d)
    bend, threshold, score = project_to_smoother(d, mix.mixture)
    return SurfaceFit(
        bend_sigma_rad=bend,
        corner_threshold=threshold,
        mixture=mix,
        rows=len(d.c),
        runs=len(runs),
        score={
            "before": float(
                expected_log_score(d, mix.mixture, before.bend_sigma_rad, before.corner_threshold)
            ),
            "after": score,
        },
        smoother_evidence={
            "before": smoother_log_evidence(runs, before.bend_sigma_rad, before.corner_threshold),
            "after": smoother_log_evidence(runs, bend, threshold),
        },
        before=before,
    )
