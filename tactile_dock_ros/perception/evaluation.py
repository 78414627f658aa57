"""Scoring a prior against a known terrain: visibility, in-view truth, 2-sigma band coverage.

Used by the tests and by the ``perception`` benchmark.
"""

from __future__ import annotations

import numpy as np

from ..core.shape import GaussianShape
from .geometry import cross2, resample_polyline

_EPS = 1e-9


def visible_from(polyline: np.ndarray, camera_xy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k,) bool: the segment camera -> point crosses no edge of the polyline before the point.

    Points are taken on the polyline itself, so a crossing within 1e-6 of the point is its own
    edge and does not count.
    """
    c = np.asarray(camera_xy, float)
    d = np.asarray(points, float)[:, None, :] - c  # (k, 1, 2)
    p, e = polyline[None, :-1], np.diff(polyline, axis=0)[None]
    denom = cross2(d, e)
    w = p - c
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross2(w, e) / denom  # along camera -> point, 1 at the point
        lam = cross2(w, d) / denom
    length = np.linalg.norm(d, axis=-1)
    blocked = (lam >= -_EPS) & (lam <= 1 + _EPS) & (s > _EPS) & (s < 1 - 1e-6 / length)
    return ~blocked.any(axis=1)


def truth_points(polyline: np.ndarray, spacing_m: float) -> np.ndarray:
    """The true terrain resampled every ``spacing_m`` along its length: (k, 2)."""
    length = np.sum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))
    return resample_polyline(polyline, max(2, int(np.ceil(length / spacing_m)) + 1))


def in_view(points: np.ndarray, camera_xy: np.ndarray, mean_vertices: np.ndarray) -> np.ndarray:
    """(k,) bool: the point's bearing from the camera lies between those of the prior's ends."""
    ref = mean_vertices.mean(axis=0) - camera_xy
    ref /= np.linalg.norm(ref)

    def bearing(q):
        r = np.asarray(q, float) - camera_xy
        return np.arctan2(ref[0] * r[..., 1] - ref[1] * r[..., 0], r @ ref)

    ends = bearing(mean_vertices)
    return (bearing(points) >= ends.min()) & (bearing(points) <= ends.max())


def band_distance(prior: GaussianShape, points: np.ndarray) -> np.ndarray:
    """(k,) smallest Mahalanobis distance of each point to the prior's polyline.

    On each edge the point is compared with the mean edge point nearest to it,
    ``m = (1 - l) mu_c + l mu_d``, under that point's covariance ``M^T C_e M`` with
    ``M = [(1 - l) I; l I]`` from the edge's 4-D Gaussian.
    """
    means, covs = prior.edge_gaussians()
    c, d = means[:, :2], means[:, 2:]
    e = d - c
    q = np.asarray(points, float)[:, None, :]
    lam = np.clip(np.sum((q - c) * e, -1) / np.maximum(np.sum(e * e, -1), 1e-300), 0, 1)
    diff = q - (c + lam[..., None] * e)  # (k, E, 2)
    a, b = (1 - lam)[..., None, None], lam[..., None, None]
    cov = (
        a * a * covs[:, :2, :2]
        + a * b * (covs[:, :2, 2:] + covs[:, 2:, :2])
        + b * b * covs[:, 2:, 2:]
    ) + 1e-12 * np.eye(2)
    d2 = np.einsum("kei,kei->ke", diff, np.linalg.solve(cov, diff[..., None])[..., 0])
    return np.sqrt(d2.min(axis=1))


def coverage(
    prior: GaussianShape,
    terrain: np.ndarray,
    camera_xy: np.ndarray,
    spacing_m: float,
    n_sigma: float = 2.0,
) -> tuple[float, int]:
    """Fraction of in-view true terrain points within ``n_sigma`` of the prior, and their count."""
    pts = truth_points(terrain, spacing_m)
    pts = pts[in_view(pts, camera_xy, prior.mean_vertices)]
    if len(pts) == 0:
        return 0.0, 0
    return float(np.mean(band_distance(prior, pts) <= n_sigma)), len(pts)
