"""Scoring a prior against a known terrain: visibility, in-view truth, 2-sigma band coverage.

Used by the tests and by the ``perception`` benchmark.
"""

from __future__ import annotations

import numpy as np

from ..core.geometry2d import cross, outward_normal
from ..core.shape import GaussianShape
from .geometry import perturb_pose, resample_polyline
from .surface import run_normals

_EPS = 1e-9


def visible_from(polyline: np.ndarray, camera_xy: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k,) bool: the segment camera -> point crosses no edge of the polyline before the point.

    Points are taken on the polyline itself, so a crossing within 1e-6 of the point is its own
    edge and does not count.
    """
    c = np.asarray(camera_xy, float)
    d = np.asarray(points, float)[:, None, :] - c  # (k, 1, 2)
    p, e = polyline[None, :-1], np.diff(polyline, axis=0)[None]
    denom = cross(d, e)
    w = p - c
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross(w, e) / denom  # along camera -> point, 1 at the point
        lam = cross(w, d) / denom
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


def scored_truth_points(
    terrain: np.ndarray, camera_xy: np.ndarray, mean_vertices: np.ndarray, spacing_m: float
) -> np.ndarray:
    """The true terrain points a prior answers for: (k, 2), ``spacing_m`` apart.

    In view (``in_view``) and, along the true polyline, between the truth points nearest to
    the prior's first and last vertex: the stretch of terrain the prior's polyline spans. Seen
    from an overhead camera, faces that lie behind the seen surface beyond the slice's ends
    (the back of a hold, a wall under a slope) are in view by bearing but are no part of the
    slice, hidden stretch or not, and are not scored.
    """
    pts = truth_points(terrain, spacing_m)
    ends = [np.argmin(np.linalg.norm(pts - v, axis=1)) for v in mean_vertices[[0, -1]]]
    index = np.arange(len(pts))
    spanned = (index >= min(ends)) & (index <= max(ends))
    return pts[spanned & in_view(pts, camera_xy, mean_vertices)]


def coverage(
    prior: GaussianShape,
    terrain: np.ndarray,
    camera_xy: np.ndarray,
    spacing_m: float,
    n_sigma: float = 2.0,
) -> tuple[float, int]:
    """Fraction of the scored true points (``scored_truth_points``) within ``n_sigma`` of the
    prior, and their count."""
    pts = scored_truth_points(terrain, camera_xy, prior.mean_vertices, spacing_m)
    if len(pts) == 0:
        return 0.0, 0
    return float(np.mean(band_distance(prior, pts) <= n_sigma)), len(pts)


def normal_deviations(
    vertices: np.ndarray, normals: np.ndarray, terrain: np.ndarray, max_distance_m: float
) -> np.ndarray:
    """(n,) signed distance t of the truth along each vertex's normal line ``v + t n``.

    The truth point matched to vertex i is the crossing of the true polyline with the line
    through ``v_i`` along ``n_i`` that is nearest to ``v_i``; NaN when no crossing lies within
    ``max_distance_m``.
    """
    v = np.asarray(vertices, float)[:, None, :]
    nrm = np.asarray(normals, float)[:, None, :]
    p, e = terrain[None, :-1], np.diff(terrain, axis=0)[None]
    denom = cross(nrm, e)
    w = p - v
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(w, e) / denom
        lam = cross(w, nrm) / denom
    t = np.where((lam >= 0) & (lam <= 1) & np.isfinite(t), t, np.inf)
    best = np.take_along_axis(t, np.argmin(np.abs(t), axis=1)[:, None], axis=1)[:, 0]
    return np.where(np.abs(best) <= max_distance_m, best, np.nan)


SCORE_NUGGET_M = 0.0005  # half a 1 mm depth step: gives rank-deficient priors a density


def matched_truth(
    mean: np.ndarray,
    hidden: np.ndarray,
    terrain: np.ndarray,
    T_plane_camera: np.ndarray,
    calibration_error: np.ndarray,
    max_distance_m: float = 0.1,
) -> np.ndarray:
    """(n, 2) the true terrain point matched to each mean vertex; NaN rows when none.

    The vertex is first moved where the camera's ray really went (its believed position under
    the true pose ``perturb_pose(T, calibration_error)``, in-plane part), then along its moved
    normal onto the truth (``normal_deviations``): the rigid motion of a calibration error is
    matched exactly, and only the surface's deviation is measured along the normal. Normals
    are those of each visible run on its own (``surface.run_normals``, as the prior uses).
    """
    T = np.asarray(T_plane_camera, float)
    M = perturb_pose(T, calibration_error) @ np.linalg.inv(T)
    moved = (np.column_stack([mean, np.zeros(len(mean)), np.ones(len(mean))]) @ M.T)[:, :2]
    normals = run_normals(mean, hidden) @ M[:2, :2].T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    t = normal_deviations(moved, normals, terrain, max_distance_m)
    return moved + t[:, None] * normals


def deviation_score(
    prior: GaussianShape, truth: np.ndarray, rng: np.random.Generator, samples: int = 1000
) -> dict:
    """Proper scores of the matched truth ``truth`` (n, 2), NaN rows skipped.

    The prior's predictive of the stacked matched points is ``N(mu, A A^T + nugget^2 I)``.
    Returns the Gaussian NLL per vertex ``(log det(2 pi S) + r^T S^-1 r) / (2 k)`` (nats, k
    scored vertices, r = truth - mu) and the energy score ``E|X - y| - E|X - X'| / 2``
    (metres) from ``samples`` draws of X (pairs split in half).
    """
    ok = np.all(np.isfinite(truth), axis=1)
    r = (truth - prior.mean_vertices)[ok].ravel()
    B = prior.basis.reshape(prior.n_vertices, 2, -1)[ok].reshape(len(r), -1)
    k = int(ok.sum())
    S = B @ B.T + SCORE_NUGGET_M**2 * np.eye(len(r))
    L = np.linalg.cholesky(S)
    w = np.linalg.solve(L, r)
    nll = (len(r) * np.log(2 * np.pi) + 2 * np.sum(np.log(np.diag(L))) + w @ w) / (2 * k)
    X = rng.standard_normal((samples, len(r))) @ L.T
    half = samples // 2
    energy = np.mean(np.linalg.norm(X - r, axis=1)) - 0.5 * np.mean(
        np.linalg.norm(X[:half] - X[half : 2 * half], axis=1)
    )
    return {"nll_per_vertex": float(nll), "energy_m": float(energy), "vertices": k}


def edge_angle_stats(prior: GaussianShape) -> tuple[np.ndarray, np.ndarray]:
    """(E,) linearized std (radians) of each edge's direction and (E - 1,) the correlation of
    neighbouring edges' directions: ``n_e^T (A_d - A_c)`` over the edge length, n_e its normal."""
    mean = prior.mean_vertices
    A = prior.basis.reshape(prior.n_vertices, 2, -1)
    e = np.diff(mean, axis=0)
    length = np.maximum(np.linalg.norm(e, axis=1), 1e-12)
    normal = outward_normal(e) / length[:, None]
    rows = np.einsum("ei,eik->ek", normal, A[1:] - A[:-1]) / length[:, None]
    std = np.linalg.norm(rows, axis=1)
    corr = np.sum(rows[:-1] * rows[1:], axis=1) / np.maximum(std[:-1] * std[1:], 1e-300)
    return std, corr


def edge_angle_errors(prior: GaussianShape, truth: np.ndarray) -> np.ndarray:
    """(k,) standardized direction errors of the edges whose both ends have a matched truth
    point (``truth`` (n, 2) from ``matched_truth``, NaN rows skipped): the wrapped angle from
    the mean edge to the chord of the two matched points, over the edge's linearized direction
    std (``edge_angle_stats``, calibration included).

    Decision: the point scores above cannot see a prior that is sharp in direction and wrong
    there (faces 4-5 cm long blurred by 2 cm bins: notch's holds); a hold is decided by an
    edge's direction against the friction cone, so its calibration is checked directly.
    """
    e = np.diff(prior.mean_vertices, axis=0)
    chord = np.diff(np.asarray(truth, float), axis=0)
    ok = np.all(np.isfinite(chord), axis=1)
    turn = np.arctan2(cross(e[ok], chord[ok]), np.sum(e[ok] * chord[ok], axis=1))
    std, _ = edge_angle_stats(prior)
    return turn / np.maximum(std[ok], 1e-12)
