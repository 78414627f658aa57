"""Visible slice -> mean and deviation columns of the true surface (the prior's depth part).

Two models (``SurfaceParams.depth_model``):

``independent`` (the original model): each visible vertex moves along its viewing ray with the
std of ONE depth pixel, independently of its neighbours. A vertex is a median of many pixels,
so this is far too wide on smooth faces, and because neighbours are independent a 2 cm edge's
angle is uncertain by tens of degrees and evidence on one edge says nothing about the next.

``correlated`` (default): a Gaussian model of the true surface given the slice.
1. Measurement: a bin median of N pixels of std sigma has std ``sqrt(pi / 2) sigma / sqrt(N)``
   (the asymptotic efficiency of the median, 1.2533 for Gaussian noise); a vertex interpolating
   two bins carries the effective N of ``slicing.resample_run``. Floors the median cannot
   average away, added in quadrature: the depth resolution ``q / sqrt(12)`` (1 mm steps of a
   16UC1 image); and at corners the chord between vertices cuts the true corner by up to the
   sagitta ``h phi / 4`` (spacing h, turn phi), about a quarter of the measured second
   difference's excess over its noise (below). Only the component along the vertex normal
   matters for the shape (a tangential shift slides the vertex along the surface); the ray's
   incidence is floored at ``_MIN_INCIDENCE`` so that a grazing view is never taken as exact.
   A run's end next to a hidden stretch sits at a depth jump: its bins mix pixels of the near
   and the far surface (mixed pixels), and the far end of the jump is where a line of sight
   grazing the occluder lands. Such an end carries half a vertex spacing of std (where in its
   bin the jump falls), and the prior has no smoothness term at its neighbour (the near end
   is the occluder's corner, where the surface may turn any way): the end keeps its measured
   position and its own std. (A std of the whole jump / sqrt(12), a mixed bin's median
   anywhere between the two ranges, was tried: the benchmark's truths never needed it.)
2. Surface prior: a piecewise smooth curve. The true second difference at vertex i along its
   normal (``h`` times the surface's turn there) is ``N(0, q_i)`` with
   ``q_i = (h bend_sigma_rad)^2 + e_i^2``: faces bend by ``bend_sigma_rad`` per vertex, and
   where the measured second difference ``c_i`` exceeds its noise std by more than
   ``corner_threshold`` (``e_i = max(|c_i| - threshold sd(c_i), 0)``) the data show a corner
   and the prior lets it be. Only turns are penalized: a straight line of any position and
   direction is free (the second difference of a linear function is zero).
3. With u the true surface's offset along the vertex normals from the measured vertices, the
   second differences of the truth are ``c + D2 u``; the Gaussian posterior of u has precision
   ``P = D2^T Q^-1 D2 + S^-1`` and mean ``-P^-1 D2^T Q^-1 c`` (a Whittaker smoother with local
   stiffness: faces are smoothed, corners kept). Its covariance ``P^-1`` is dense: on a face a
   straight line is determined by all of its pixels together, so neighbouring edges' angles
   are strongly correlated and evidence on one edge moves its neighbours.
4. ``P^-1`` of each visible run (runs are independent: a hidden stretch separates surfaces)
   is compressed to its leading eigen-columns holding ``variance_kept`` of its trace; they
   move each vertex along the normal of the posterior mean (where the offsets were taken
   along the measured normals: the same to first order, but not at a shifted run end).
Hidden vertices carry the linear interpolation of their stretch's end rows in both models, so a
hidden stretch moves with the ends it hangs from.
"""

from __future__ import annotations

import numpy as np

from ..core import prior as core_prior
from .config import DepthNoise, Extrinsic, SurfaceParams
from .slicing import TerrainSlice

MEDIAN_EFFICIENCY = float(np.sqrt(np.pi / 2))  # std(median of N) * sqrt(N) / sigma, large N
_MIN_INCIDENCE = 0.1  # |cos| between ray and normal: a view grazing below ~6 degrees
_MIN_SIGMA_M = 1e-6  # a noise-free, unquantized image still gives a (1 um) positive variance


def camera_depths(vertices: np.ndarray, extrinsic: Extrinsic) -> np.ndarray:
    """(n,) optical-axis depth (metres) of plane points (x, y, 0) in the nominal camera."""
    rel = np.column_stack([vertices, np.zeros(len(vertices))]) - extrinsic.camera_centre
    return rel @ extrinsic.rotation[:, 2]


def ray_sigma(
    terrain: TerrainSlice,
    extrinsic: Extrinsic,
    noise: DepthNoise,
    surface: SurfaceParams,
) -> np.ndarray:
    """(n,) std (metres) of each vertex along its in-plane viewing ray; 0 for hidden ones.

    ``independent``: one pixel's sigma(z); ``correlated``: the median of the vertex's pixels
    plus the depth resolution (see module docstring). Depth errors are scaled to the in-plane
    range by ``|p - c|_xy / z``.
    """
    v = terrain.vertices
    z = np.maximum(camera_depths(v, extrinsic), 1e-6)
    scale = np.linalg.norm(v - terrain.camera_xy, axis=1) / z
    pixel = noise.sigma(z) * scale
    if surface.depth_model == "independent":
        sigma = pixel
    else:
        count = np.maximum(terrain.pixels, 1.0)
        resolution = surface.quantization_m / np.sqrt(12.0) * scale
        sigma = np.sqrt((MEDIAN_EFFICIENCY * pixel) ** 2 / count + resolution**2)
    return np.where(terrain.hidden, 0.0, sigma)


def visible_runs(hidden: np.ndarray) -> list[tuple[int, int]]:
    """(first, stop) index ranges of the maximal runs of visible vertices."""
    edges = np.flatnonzero(np.diff(np.r_[1, np.asarray(hidden, int), 1]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def run_normals(vertices: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """(n, 2) unit normals of each visible run on its own (one-sided at a run's ends, never
    through a hidden neighbour); hidden vertices get the normals of the whole polyline."""
    normals = core_prior.vertex_normals(vertices)
    for lo, hi in visible_runs(hidden):
        if hi - lo >= 2:
            normals[lo:hi] = core_prior.vertex_normals(vertices[lo:hi])
    return normals


def normal_noise(
    vertices: np.ndarray,
    rays: np.ndarray,
    sigma: np.ndarray,
    spacing_m: float,
    jump_ends: tuple[bool, bool] = (False, False),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals (r, 2), measurement variance along them (r,) and measured second differences
    along them (r - 2,) of one visible run (step 1; ``surface_fit`` fits step 2 on these).

    The variance is the ray std's normal component (incidence floored) with the half-spacing
    std of a run end at a depth jump (``jump_ends``); the sagitta floor, which depends on the
    excess over the corner threshold, is added by ``smooth_run``.
    """
    normals = core_prior.vertex_normals(vertices)
    incidence = np.maximum(np.abs(np.sum(rays * normals, axis=1)), _MIN_INCIDENCE)
    s2 = np.maximum(sigma * incidence, _MIN_SIGMA_M) ** 2
    s2[[0, -1]] += np.where(np.asarray(jump_ends, bool), (spacing_m / 2) ** 2, 0.0)
    second = vertices[:-2] - 2 * vertices[1:-1] + vertices[2:]
    return normals, s2, np.sum(second * normals[1:-1], axis=1)


def smooth_run(
    vertices: np.ndarray,
    rays: np.ndarray,
    sigma: np.ndarray,
    spacing_m: float,
    surface: SurfaceParams,
    jump_ends: tuple[bool, bool] = (False, False),
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean (r, 2) and deviation columns (r, 2, k) of one visible run (steps 1-4).

    ``jump_ends``: whether the first / last vertex borders a hidden stretch (a depth jump).
    """
    r = len(vertices)
    normals, s2, c = normal_noise(vertices, rays, sigma, spacing_m, jump_ends)
    jump = np.asarray(jump_ends, bool)
    shift = np.zeros(r)
    if r >= 3:
        sd_c = np.sqrt(s2[:-2] + 4 * s2[1:-1] + s2[2:])
        excess = np.maximum(np.abs(c) - surface.corner_threshold * sd_c, 0.0)
        s2[1:-1] += (excess / 4) ** 2
        q = (spacing_m * surface.bend_sigma_rad) ** 2 + excess**2
        stiff = np.ones(r - 2)  # 0: no smoothness where a run ends at a jump (a free corner)
        stiff[[0, -1]] *= ~jump
        D2 = np.zeros((r - 2, r))
        idx = np.arange(r - 2)
        D2[idx, idx], D2[idx, idx + 1], D2[idx, idx + 2] = 1.0, -2.0, 1.0
        precision = D2.T @ (D2 * (stiff / q)[:, None]) + np.diag(1.0 / s2)
        cov = np.linalg.inv(precision)
        cov = 0.5 * (cov + cov.T)
        shift = cov @ (D2.T @ (-c * stiff / q))
    else:
        cov = np.diag(s2)
    values, vectors = np.linalg.eigh(cov)
    values, vectors = np.clip(values[::-1], 0.0, None), vectors[:, ::-1]
    k = int(np.searchsorted(np.cumsum(values), surface.variance_kept * values.sum()) + 1)
    amplitudes = vectors[:, :k] * np.sqrt(values[:k])
    mean = vertices + shift[:, None] * normals
    return mean, core_prior.vertex_normals(mean)[:, :, None] * amplitudes[:, None, :]


def run_inputs(terrain: TerrainSlice):
    """Per visible run of the slice: (first, stop, unit rays from the camera (r, 2), whether its
    first / last vertex borders a hidden stretch), as ``smooth_run`` takes them."""
    rel = terrain.vertices - terrain.camera_xy
    rays = rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-12)
    jump = np.zeros(len(rel), bool)
    jump[terrain.stretches.ravel()] = True
    for lo, hi in visible_runs(terrain.hidden):
        yield lo, hi, rays[lo:hi], (bool(jump[lo]), bool(jump[hi - 1]))


def surface_columns(
    terrain: TerrainSlice,
    extrinsic: Extrinsic,
    noise: DepthNoise,
    surface: SurfaceParams,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean vertices (n, 2) and depth columns (2n, k) of the slice under ``surface``."""
    verts = terrain.vertices.copy()
    n = len(verts)
    sigma = ray_sigma(terrain, extrinsic, noise, surface)
    if surface.depth_model == "independent":
        cols = core_prior.ray_columns(verts, terrain.camera_xy, sigma).reshape(n, 2, -1)
        cols = cols[:, :, ~terrain.hidden]
    else:
        blocks = []
        for lo, hi, rays, jump_ends in run_inputs(terrain):
            verts[lo:hi], run_cols = smooth_run(
                verts[lo:hi], rays, sigma[lo:hi], terrain.spacing_m, surface, jump_ends
            )
            block = np.zeros((n, 2, run_cols.shape[2]))
            block[lo:hi] = run_cols
            blocks.append(block)
        cols = np.concatenate(blocks, axis=2)
    for first, last in terrain.stretches:
        inner = np.arange(first + 1, last)
        lam = ((inner - first) / (last - first))[:, None, None]
        cols[inner] = (1 - lam) * cols[first] + lam * cols[last]
        verts[inner] = (1 - lam[:, :, 0]) * verts[first] + lam[:, :, 0] * verts[last]
    return verts, cols.reshape(2 * n, -1)
