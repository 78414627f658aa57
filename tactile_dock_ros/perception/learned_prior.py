"""Learned terrain prior: per-class Gaussians conditioned on a depth image (paper Sec. III-A1).

The paper's prior is a Gaussian ``x = mu + A z`` over the polyline vertices. Here the Gaussian is
learned, one per terrain class, from training truths, and conditioned on the depth image instead
of being built from the image alone (``terrain_prior.perceive``).

Model. A class (:class:`TerrainClass`) holds the mean ``mu`` (n, 2) of training truths that share
a vertex correspondence (vertex i is the same feature in all of them) and a basis ``A`` whose
first columns are the PCA directions scaled by their standard deviations (kept to
``variance_kept`` of the variance) and whose last 2n columns are an isotropic floor
``f I``: ``f = max(floor_m, sqrt(dropped variance / 2n))``, so the dropped directions and the
PCA's own sampling error keep some spread and no truth has zero density (:func:`fit_class`).
The floor is independent noise per vertex, which tilts short edges; it is kept small
(``VARIANCE_KEPT`` 0.99999, ``FLOOR_M`` 0.05 mm) so that a class's draws hold the load on as
many edges as the shapes it describes (``tools.fit_terrain_classes.holding_check``: with 99.9 %
kept, three_ledges' dropped 0.1 % became a 0.71 mm floor and 1.32x as many holding edges).

Measurement model. The image goes through the project's slice extraction
(``slicing.band_points`` + ``slicing.profile_from_points``): per bearing bin one point, i.e. one
ray from the (nominal) camera centre along unit bearing ``u_k`` with measured range ``rho_k``. The
predicted range is the first hit of that ray on the polyline ``mu + A z + C w``, where ``C`` are
the extrinsic's calibration columns (``terrain_prior.calibration_columns``, linearized at the
class mean): the image was taken from a displaced pose, which moves every seen point by the same
rigid in-plane motion. Noise per bin: the median of ``N`` pixels of depth std ``s`` along the ray
has std ``1.2533 s / sqrt(N)``, in quadrature with a model floor (``MODEL_FLOOR_M``: binning,
the bin's slope regression, the polyline's straight edges).

Decisions.
- Inference is Gauss-Newton on the joint ``v = (z, w) ~ N(0, I)`` (an iterated extended Kalman
  update: each step solves the linearized problem from the prior, not from the last step), a
  loop over ``ANNEAL``: the noise is inflated by ``tau`` in quadrature, from 3 cm down to 0, so
  that early steps, linearized far from the truth, do not lock onto a wrong edge.
- Gating: a bin whose residual exceeds ``GATE`` effective stds (or whose ray misses the
  polyline) is an outlier with a fixed density (``OUTLIER_LOG_DENSITY``: 1 % of bins spread over
  1 m of range); it does not update, and it costs that density in the evidence. Depth jumps,
  mixed pixels and the wrong class's missing faces land there instead of bending the fit.
- Evidence: Laplace at the final estimate (noise not inflated), ``log p(rho | class) ~
  log p(rho | v*) - |v*|^2 / 2 - log det(I + H^T W H) / 2``; the class with the largest is
  chosen (equal class priors). Per ray, the log-likelihood terms are returned
  (``LearnedPrior.ray_log_evidence``) with the inlier fraction, so a caller can see which part of
  the image a class does not explain.
- Posterior: the shape block of ``(I + H^T W H)^-1`` pushed through ``A``, truncated by an
  eigendecomposition to ``keep`` of its trace; the calibration is marginalized out, because the
  truth is where the tool will touch, in the plane frame, whatever the camera's error was.
- Inlier fraction (``ClassFit.inlier_fraction``): the share of the slice bins the class explains,
  leaving out bins next to a range step of more than ``DEPTH_STEP_M`` between neighbouring bins
  (``SliceRays.at_depth_step``). Such a bin's median mixes two surfaces (an occluding edge, the
  slice's grazing first rays), which no polyline explains whatever the class; counted, they
  made the well-fitted notch scans look out of library (measured, 300 train scans per class,
  1 % quantile of notch's own inlier fraction 0.935 counted, 0.972 left out; the 99 % quantile
  of the walls other classes are taken for by notch 0.961 and 0.963). They still cost the
  outlier density in the evidence. Steps of 1-3 cm give the same quantiles within 0.003.
- :func:`condition` returns the best class whatever its fit; the out-of-library gate (the best
  class's inlier fraction against that class's ``min_inlier_fraction``, fitted on training
  scans by ``tools.fit_terrain_classes``) is ``perception.prior_select``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..core.shape import GaussianShape
from .config import PerceptionConfig, PerceptionError
from .slicing import band_points, profile_from_points
from .terrain_prior import calibration_columns

FORMAT_VERSION = 3  # 2: one min_inlier_fraction; 3: one per class; 1: none
READABLE_VERSIONS = (1, 2, 3)
FLOOR_M = 0.00005  # isotropic floor std per coordinate of a class, metres
VARIANCE_KEPT = 0.99999  # share of the training variance a class's PCA keeps
MODEL_FLOOR_M = 0.0005  # per-bin range error floor (binning, slope regression), metres
MEDIAN_EFFICIENCY = 1.2533  # std of a median of N normal draws is ~ 1.2533 sigma / sqrt(N)
OUTLIER_LOG_DENSITY = float(np.log(0.01 / 1.0))  # an outlier bin: 1 % spread over 1 m of range
ANNEAL = (0.03, 0.015, 0.008, 0.004, 0.002, 0.001, 0.0, 0.0, 0.0, 0.0)  # noise inflation, m
GATE = 5.0  # residuals beyond GATE effective stds are outliers
DEPTH_STEP_M = 0.02  # a bin next to a range step this large is not counted by the gate
MIN_BINS = 3  # fewer slice bins than this: no prior


@dataclass(frozen=True)
class TerrainClass:
    """One terrain class: ``x = mean.ravel() + basis z``, ``z ~ N(0, I)``.

    Attributes:
        name: class name (a ``core.problems`` name for the shipped library).
        mean: (n, 2) mean vertices, plane frame, metres.
        basis: (2n, m) columns: scaled PCA directions, then the isotropic floor.
        closed: whether edge (n-1, 0) exists.
        friction: Coulomb friction coefficient of the class's surface.
        min_inlier_fraction: the class's out-of-library gate (``perception.prior_select``),
            fitted on training scans; None: not fitted (a caller must give one).
    """

    name: str
    mean: np.ndarray
    basis: np.ndarray
    closed: bool = False
    friction: float = 0.5
    min_inlier_fraction: float | None = None

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=float)
        basis = np.asarray(self.basis, dtype=float)
        if not self.name:
            raise ValueError("a terrain class needs a name")
        if mean.ndim != 2 or mean.shape[1] != 2 or len(mean) < 2:
            raise ValueError(f"{self.name}: mean must be (n >= 2, 2), got {mean.shape}")
        if basis.ndim != 2 or basis.shape[0] != mean.size:
            raise ValueError(f"{self.name}: basis must be ({mean.size}, m), got {basis.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(basis))):
            raise ValueError(f"{self.name}: mean and basis must be finite")
        if not (np.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"{self.name}: friction must be finite and >= 0, got {self.friction}")
        gate = self.min_inlier_fraction
        if gate is not None and not (np.isfinite(gate) and 0.0 <= gate <= 1.0):
            raise ValueError(
                f"{self.name}: min_inlier_fraction must be in [0, 1] or None, got {gate}"
            )
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "basis", basis)
        object.__setattr__(self, "closed", bool(self.closed))
        object.__setattr__(self, "friction", float(self.friction))
        object.__setattr__(self, "min_inlier_fraction", None if gate is None else float(gate))

    @property
    def n_vertices(self) -> int:
        return len(self.mean)

    @property
    def covariance(self) -> np.ndarray:
        """(2n, 2n) ``basis basis^T``."""
        return self.basis @ self.basis.T


@dataclass(frozen=True)
class TerrainLibrary:
    """The terrain classes the image is explained by; ``save`` / ``load`` as .npz."""

    classes: tuple[TerrainClass, ...]

    def __post_init__(self) -> None:
        classes = tuple(self.classes)
        if not classes:
            raise ValueError("a terrain library needs at least one class")
        names = [c.name for c in classes]
        if len(set(names)) != len(names):
            raise ValueError(f"class names must be unique, got {names}")
        object.__setattr__(self, "classes", classes)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.classes]

    def get(self, name: str) -> TerrainClass:
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(f"no class {name!r} in the library ({self.names})")

    @property
    def gates(self) -> dict[str, float | None]:
        """Each class's ``min_inlier_fraction`` by name."""
        return {c.name: c.min_inlier_fraction for c in self.classes}

    def with_gates(self, gates: dict[str, float | None]) -> TerrainLibrary:
        """This library with each class's gate replaced by ``gates[name]`` (KeyError when a
        class has none)."""
        return TerrainLibrary(
            tuple(replace(c, min_inlier_fraction=gates[c.name]) for c in self.classes)
        )

    def without(self, name: str) -> TerrainLibrary:
        """This library without class ``name`` (the others keep their gates)."""
        return TerrainLibrary(tuple(c for c in self.classes if c.name != name))

    def save(self, path: Path | str) -> None:
        """Write ``path`` (.npz, no pickles): ``format_version``, ``names``, and per class i
        ``mean_i``, ``basis_i``, ``closed_i``, ``friction_i``, ``min_inlier_fraction_i`` (NaN:
        none)."""
        arrays = {
            "format_version": np.array(FORMAT_VERSION),
            "names": np.array(self.names, dtype=str),
        }
        for i, c in enumerate(self.classes):
            gate = np.nan if c.min_inlier_fraction is None else c.min_inlier_fraction
            arrays[f"mean_{i}"] = c.mean
            arrays[f"basis_{i}"] = c.basis
            arrays[f"closed_{i}"] = np.array(c.closed)
            arrays[f"friction_{i}"] = np.array(c.friction)
            arrays[f"min_inlier_fraction_{i}"] = np.array(gate)
        with open(path, "wb") as f:  # np.savez(path) would append .npz to other suffixes
            np.savez_compressed(f, **arrays)

    @classmethod
    def load(cls, path: Path | str) -> TerrainLibrary:
        """Read a library written by ``save`` (format 2's one gate becomes every class's; format
        1 has none). Raises ValueError naming the file when it is not one (unreadable, another
        format version, missing or malformed entries)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except FileNotFoundError:
            raise
        except Exception as err:  # zipfile / pickle / OSError: not an .npz we can read
            raise ValueError(f"{path}: not a terrain class library (.npz): {err}") from err
        if "format_version" not in arrays:
            raise ValueError(f"{path}: not a terrain class library (no format_version)")
        version = arrays["format_version"]
        if version.shape != () or int(version) not in READABLE_VERSIONS:
            readable = " and ".join(map(str, READABLE_VERSIONS))
            raise ValueError(
                f"{path}: terrain class library format {version.tolist()}, this code reads "
                f"{readable} (refit with tools.fit_terrain_classes)"
            )
        version = int(version)

        def gate(i: int) -> float | None:
            if version == 1:
                return None
            value = float(
                arrays["min_inlier_fraction" if version == 2 else f"min_inlier_fraction_{i}"]
            )
            return None if np.isnan(value) else value

        try:
            names = [str(n) for n in arrays["names"]]
            return cls(
                tuple(
                    TerrainClass(
                        name,
                        arrays[f"mean_{i}"],
                        arrays[f"basis_{i}"],
                        bool(arrays[f"closed_{i}"]),
                        float(arrays[f"friction_{i}"]),
                        gate(i),
                    )
                    for i, name in enumerate(names)
                )
            )
        except (KeyError, ValueError, TypeError) as err:
            raise ValueError(f"{path}: malformed terrain class library: {err}") from err


def fit_class(
    name: str,
    truths: np.ndarray | Sequence[np.ndarray],
    closed: bool = False,
    friction: float = 0.5,
    variance_kept: float = VARIANCE_KEPT,
    floor_m: float = FLOOR_M,
) -> TerrainClass:
    """PCA Gaussian of training truths (N, n, 2) that share a vertex correspondence.

    Keeps the leading directions holding ``variance_kept`` of the sample variance (unbiased,
    ``N - 1``), scaled by their stds, and appends the isotropic floor ``f I`` with
    ``f = max(floor_m, sqrt(dropped variance / 2n))``."""
    X = np.asarray(truths, dtype=float)
    if X.ndim != 3 or X.shape[2] != 2:
        raise ValueError(f"truths must be (N, n, 2) with one vertex count, got {X.shape}")
    N, n = X.shape[:2]
    if N < 2:
        raise ValueError(f"need at least 2 truths to fit a class, got {N}")
    if not 0.0 < variance_kept <= 1.0:
        raise ValueError(f"variance_kept must be in (0, 1], got {variance_kept}")
    if not (np.isfinite(floor_m) and floor_m > 0):
        raise ValueError(f"floor_m must be finite and > 0, got {floor_m}")
    X = X.reshape(N, 2 * n)
    mu = X.mean(axis=0)
    _, s, vt = np.linalg.svd(X - mu, full_matrices=False)
    basis = _pca_basis(s**2 / (N - 1), vt.T, variance_kept, floor_m)
    return TerrainClass(name, mu.reshape(n, 2), basis, closed, friction)


def class_from_moments(
    terrain: TerrainClass,
    mean: np.ndarray,
    covariance: np.ndarray,
    variance_kept: float = VARIANCE_KEPT,
    floor_m: float = FLOOR_M,
) -> TerrainClass:
    """``terrain`` (name, closedness, friction, gate) with a new mean (2n,) and covariance
    (2n, 2n), truncated as ``fit_class`` truncates a sample covariance."""
    values, vectors = np.linalg.eigh(0.5 * (covariance + covariance.T))
    order = np.argsort(values)[::-1]
    basis = _pca_basis(values[order].clip(0.0), vectors[:, order], variance_kept, floor_m)
    return replace(terrain, mean=np.asarray(mean, float).reshape(-1, 2), basis=basis)


def _pca_basis(var: np.ndarray, vectors: np.ndarray, variance_kept: float, floor_m: float):
    """Columns: the leading directions (``vectors`` columns, variances ``var`` descending)
    holding ``variance_kept`` of the variance, scaled by their stds, then ``f I`` with
    ``f = max(floor_m, sqrt(dropped variance / dim))``."""
    dim = vectors.shape[0]
    total = var.sum()
    if total > 0:
        k = int(np.searchsorted(np.cumsum(var) / total, variance_kept - 1e-12) + 1)
        k = min(k, len(var))
    else:
        k = 0
    floor = max(floor_m, float(np.sqrt(var[k:].sum() / dim)))
    return np.hstack([vectors[:, :k] * np.sqrt(var[:k]), floor * np.eye(dim)])


@dataclass(frozen=True)
class SliceRays:
    """The image's slice as rays from the nominal camera centre ``origin`` (2,)."""

    points: np.ndarray  # (k, 2) bin-median points, plane frame
    bearings: np.ndarray  # (k, 2) unit vectors
    ranges: np.ndarray  # (k,)
    sigma: np.ndarray  # (k,) range std
    origin: np.ndarray  # (2,)

    @property
    def at_depth_step(self) -> np.ndarray:
        """(k,) bins whose range differs from a neighbour's by more than ``DEPTH_STEP_M``."""
        step = np.abs(np.diff(self.ranges)) > DEPTH_STEP_M
        return np.r_[step, False] | np.r_[False, step]


def slice_rays(depth: np.ndarray, K: np.ndarray, config: PerceptionConfig) -> SliceRays:
    """The depth image's slice bins as rays (see the module docstring). Raises PerceptionError
    when the band holds fewer than ``MIN_BINS`` bins."""
    noise = config.depth_noise
    depth = np.asarray(depth, dtype=float)
    with np.errstate(invalid="ignore"):
        depth = np.where((depth >= noise.min_range_m) & (depth <= noise.max_range_m), depth, np.nan)
    points = band_points(
        depth, np.asarray(K, float), config.extrinsic, config.slice.band_half_width_m
    )
    origin = np.asarray(config.extrinsic.camera_centre[:2], float).copy()
    profile, counts = profile_from_points(
        points, origin, config.slice.vertex_spacing_m, config.slice.gap_m
    )
    if len(profile) < MIN_BINS:
        raise PerceptionError(f"{len(profile)} slice bins, need at least {MIN_BINS}")
    rel = profile - origin
    ranges = np.linalg.norm(rel, axis=1)
    bearings = rel / ranges[:, None]
    axis = config.extrinsic.rotation[:2, 2]  # in-plane part of the optical axis
    along = rel @ axis  # the depth the camera measured
    sigma_pixel = noise.sigma(along) * ranges / np.maximum(along, 1e-6)
    sigma = np.sqrt((MEDIAN_EFFICIENCY * sigma_pixel) ** 2 / counts + MODEL_FLOOR_M**2)
    return SliceRays(profile, bearings, ranges, sigma, origin)


def _edges(n: int, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    first = np.arange(n if closed else n - 1)
    return first, (first + 1) % n


def ray_hits(vertices: np.ndarray, closed: bool, origin: np.ndarray, bearings: np.ndarray):
    """First hit of each ray ``origin + r u`` on the polyline: range (k,) (inf: a miss), edge
    index (k,) and position along the edge (k,) in [0, 1]."""
    i0, i1 = _edges(len(vertices), closed)
    a, e = vertices[i0], vertices[i1] - vertices[i0]
    w = a - origin
    u = bearings
    denom = u[:, None, 0] * e[None, :, 1] - u[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / denom
        lam = (w[None, :, 0] * u[:, None, 1] - w[None, :, 1] * u[:, None, 0]) / denom
    ok = (lam >= 0) & (lam <= 1) & (r > 0) & np.isfinite(r)
    r = np.where(ok, r, np.inf)
    j = np.argmin(r, axis=1)
    k = np.arange(len(u))
    hit = r[k, j]
    return hit, j, np.where(np.isfinite(hit), lam[k, j], 0.0)


def range_jacobian(vertices, closed, bearings, edge, lam, use) -> np.ndarray:
    """(k, 2n) d range / d vertices for rays hitting ``edge`` at ``lam``; rows not in ``use``
    are zero."""
    n = len(vertices)
    i0, i1 = _edges(n, closed)
    a, b = i0[edge], i1[edge]
    e = vertices[b] - vertices[a]
    normal = np.stack([-e[:, 1], e[:, 0]], axis=1)
    nu = np.einsum("ij,ij->i", normal, bearings)
    g = normal / np.where(np.abs(nu) < 1e-12, 1e-12, nu)[:, None]
    J = np.zeros((len(bearings), 2 * n))
    k = np.flatnonzero(use)
    for d in range(2):
        np.add.at(J, (k, 2 * a[k] + d), (1 - lam[k]) * g[k, d])
        np.add.at(J, (k, 2 * b[k] + d), lam[k] * g[k, d])
    return J


@dataclass(frozen=True)
class ClassFit:
    """One class conditioned on the image."""

    name: str
    prior: GaussianShape  # posterior over the class's vertices, calibration marginalized
    log_evidence: float
    inliers: np.ndarray  # (k,) bool
    ray_log_evidence: np.ndarray  # (k,) per-bin log-likelihood at the estimate
    calibration: np.ndarray  # (r,) posterior mean of the calibration coordinates w
    covariance: np.ndarray = field(repr=False)  # (2n, 2n) posterior covariance of the vertices
    counted: np.ndarray = field(repr=False)  # (k,) bins the inlier fraction counts

    @property
    def inlier_fraction(self) -> float:
        """Share of the counted bins (``SliceRays.at_depth_step`` left out) the class explains;
        0 when none is counted."""
        return float(np.mean(self.inliers[self.counted])) if self.counted.any() else 0.0


@dataclass(frozen=True)
class LearnedPrior:
    """Result of :func:`condition`: the chosen class's fit and every class's log-evidence."""

    best: ClassFit
    fits: tuple[ClassFit, ...]  # every class, best first
    rays: SliceRays

    @property
    def name(self) -> str:
        return self.best.name

    @property
    def prior(self) -> GaussianShape:
        return self.best.prior

    @property
    def log_evidence(self) -> dict[str, float]:
        return {f.name: f.log_evidence for f in self.fits}

    @property
    def inlier_fraction(self) -> float:
        return self.best.inlier_fraction

    @property
    def ray_log_evidence(self) -> np.ndarray:
        return self.best.ray_log_evidence


def condition_class(
    terrain: TerrainClass, rays: SliceRays, config: PerceptionConfig, keep: float = 0.9999
) -> ClassFit:
    """``terrain`` conditioned on ``rays`` (see the module docstring)."""
    C = calibration_columns(terrain.mean, config.extrinsic)  # measured = x + C w
    A = terrain.basis
    B = np.hstack([A, C])
    mu = terrain.mean.ravel()
    d, m = B.shape[1], A.shape[1]
    rho, sig, u, c = rays.ranges, rays.sigma, rays.bearings, rays.origin

    def linearize(v: np.ndarray, tau: float):
        verts = (mu + B @ v).reshape(-1, 2)
        r, j, lam = ray_hits(verts, terrain.closed, c, u)
        s_eff = np.sqrt(sig**2 + tau**2)
        hit = np.isfinite(r)
        res = np.where(hit, rho - r, np.inf)
        inl = hit & (np.abs(res) <= GATE * s_eff)
        H = range_jacobian(verts, terrain.closed, u, j, lam, inl) @ B
        W = np.where(inl, 1.0 / s_eff**2, 0.0)
        HtW = H.T * W
        return np.eye(d) + HtW @ H, HtW, H, np.where(inl, res, 0.0), inl

    v = np.zeros(d)
    for tau in ANNEAL:
        info, HtW, H, res, _ = linearize(v, tau)
        v = np.linalg.solve(info, HtW @ (res + H @ v))
    info, _, _, res, inl = linearize(v, 0.0)
    L = np.linalg.cholesky(info)
    log_det_post = -2.0 * np.sum(np.log(np.diag(L)))
    per_ray = np.where(
        inl, -0.5 * (res / sig) ** 2 - np.log(sig * np.sqrt(2 * np.pi)), OUTLIER_LOG_DENSITY
    )
    log_ev = float(per_ray.sum() - 0.5 * v @ v + 0.5 * log_det_post)
    Linv = np.linalg.solve(L, np.eye(d))
    P = Linv.T @ Linv
    mean = mu + A @ v[:m]
    cov = A @ P[:m, :m] @ A.T
    values, vectors = np.linalg.eigh(cov)
    values, vectors = values[::-1].clip(0), vectors[:, ::-1]
    k = int(np.searchsorted(np.cumsum(values) / values.sum(), keep) + 1)
    basis = vectors[:, :k] * np.sqrt(values[:k])
    prior = GaussianShape(mean, basis, closed=terrain.closed, friction=terrain.friction)
    counted = ~rays.at_depth_step
    return ClassFit(terrain.name, prior, log_ev, inl, per_ray, v[m:].copy(), cov, counted)


def condition(
    library: TerrainLibrary,
    depth: np.ndarray,
    K: np.ndarray,
    config: PerceptionConfig,
    keep: float = 0.9999,
) -> LearnedPrior:
    """Every class of ``library`` conditioned on the depth image (intrinsics ``K``, the
    extrinsic, depth noise and slice settings of ``config``); the class of largest Laplace
    evidence is chosen. Raises PerceptionError when the image gives too few slice bins."""
    return condition_rays(library, slice_rays(depth, K, config), config, keep)


def condition_rays(
    library: TerrainLibrary, rays: SliceRays, config: PerceptionConfig, keep: float = 0.9999
) -> LearnedPrior:
    """:func:`condition` on an image's slice rays (``slice_rays``)."""
    fits = sorted(
        (condition_class(c, rays, config, keep) for c in library.classes),
        key=lambda f: -f.log_evidence,
    )
    return LearnedPrior(fits[0], tuple(fits), rays)
