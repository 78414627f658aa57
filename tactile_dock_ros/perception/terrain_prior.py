"""Terrain slice -> Gaussian shape prior x = A z + mu (paper Sec. III-A1), and the whole pipeline.

Columns of A, in this order:
- calibration: the extrinsic's 6x6 covariance pushed through the linearized in-plane motion of
  each vertex, ``dp = t + r x (p - c)`` (c = camera centre, p on the plane): (tx, ty) are the
  paper's translation columns, rz its small-angle rotation about the sensor, and an off-plane
  camera (c_z != 0) turns the tilts rx, ry into in-plane translations ``(0, c_z rx)``,
  ``(-c_z ry, 0)``; tz moves the extruded terrain along itself and has no in-plane effect.
  The block is compressed by an SVD to its non-zero directions (same A A^T).
- surface: the true surface's deviation from the slice (``surface``): by default a smoothed
  mean and the correlated posterior columns of each visible run (noise of a median of N pixels,
  a piecewise smooth surface prior); ``depth_model: independent`` gives the original one
  column per visible vertex along its ray with one pixel's std. Hidden vertices interpolate
  their stretch's end rows.
- occlusion: per hidden stretch, the PCA columns of the constrained Brownian bridge
  (``bridge.occlusion_columns``); its sample mean replaces the chord placeholders in mu.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import prior as core_prior
from ..core.shape import GaussianShape
from .bridge import Sampler, occlusion_columns, sample_truncated_gaussian
from .config import DepthNoise, Extrinsic, OcclusionParams, PerceptionConfig, SurfaceParams
from .geometry import perturb_pose
from .slicing import TerrainSlice, extract_slice
from .surface import surface_columns


def calibration_jacobian(vertices: np.ndarray, camera_centre: np.ndarray) -> np.ndarray:
    """(2n, 6) in-plane vertex motion per (tx, ty, tz, rx, ry, rz) of the config convention."""
    n = len(vertices)
    unit = core_prior.translation_columns(n, 1.0, 1.0)
    cz = camera_centre[2]
    return np.hstack(
        [
            unit,
            np.zeros((2 * n, 1)),
            cz * unit[:, 1:2],  # rx: r x (p - c) has y-part -rx (p_z - c_z) = rx c_z
            -cz * unit[:, 0:1],  # ry: x-part ry (p_z - c_z) = -ry c_z
            core_prior.rotation_column(vertices, camera_centre[:2], 1.0),
        ]
    )


def calibration_columns(vertices: np.ndarray, extrinsic: Extrinsic) -> np.ndarray:
    """(2n, r <= 3) columns whose outer product is J Sigma J^T (see module docstring)."""
    values, vectors = np.linalg.eigh(extrinsic.covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    block = calibration_jacobian(vertices, extrinsic.camera_centre) @ root
    u, sv, _ = np.linalg.svd(block, full_matrices=False)
    keep = sv > 1e-9 * max(sv.max(initial=0.0), 1e-300)
    return u[:, keep] * sv[keep]


def calibration_transform(vertices: np.ndarray, extrinsic: Extrinsic):
    """Mean shift (n, 2) and columns (2n, r) of the calibration error, without linearizing.

    The unscented transform of the exact map: a vertex believed at p (nominal pose) is truly at
    ``T(delta) T_nominal^-1 p`` (``geometry.perturb_pose``; an extruded terrain, so only the
    in-plane part counts), evaluated at the 12 sigma points ``+-sqrt(6)`` eigen-stds of the
    extrinsic covariance. Rotations of 1-2 degrees at a metre's range move points by up to
    half a millimetre more than ``calibration_columns`` says (``r phi^2 / 2``), which is more
    than a well-averaged face's own noise; this keeps that second-order part (mean and spread).
    """
    values, vectors = np.linalg.eigh(extrinsic.covariance)
    root = vectors * np.sqrt(6.0 * np.clip(values, 0.0, None))
    T = extrinsic.T_plane_camera
    back = np.linalg.inv(T)
    points = np.column_stack([vertices, np.zeros(len(vertices)), np.ones(len(vertices))])
    moved = (
        np.stack(
            [points @ (perturb_pose(T, sign * d) @ back).T for d in root.T for sign in (1.0, -1.0)]
        )[:, :, :2]
        - vertices
    )  # (12, n, 2)
    mean = moved.mean(axis=0)
    spread = (moved - mean).reshape(len(moved), -1).T / np.sqrt(len(moved))
    u, sv, _ = np.linalg.svd(spread, full_matrices=False)
    keep = sv > 1e-6 * max(sv.max(initial=0.0), 1e-300)
    return mean, u[:, keep] * sv[keep]


def add_tails(
    verts: np.ndarray,
    basis: np.ndarray,
    camera_xy: np.ndarray,
    occlusion: OcclusionParams,
    spacing_m: float,
    rng: np.random.Generator,
    sampler: Sampler,
) -> tuple[np.ndarray, np.ndarray]:
    """Hidden tails of ``occlusion.tail_m`` past both ends of the slice, along the line of sight.

    Past an end the camera saw nothing (a silhouette or the image border): the terrain goes on
    somewhere behind the ray through the end vertex. Without a tail the open polyline lets a
    path pass around the end through what may be rock: behind a silhouette (the top of a hold
    seen from above) plans went over the top and down its hidden back (notch truth 0 of
    ``bench docking``). The planner's mean solid extends the end edges (``core.freespace.
    solid_region``), with tails along the rays.
    ``occlusion.tail_model``:
    - ``ray`` (decision, the profiles' setting): one straight edge per end, from the end
      vertex along the ray away from the camera, its far vertex moving with the end vertex's
      rows (no new columns). It is the boundary of the space the camera saw free: the solid
      side of it is unseen, and the planner's mean solid then covers everything behind the
      slice. No columns: nothing behind the ray was measured, and a spread lets samples
      swing the tail into the seen-free space.
    - ``bridge``: a Brownian motion from the end vertex along that ray
      (``occlusion_columns(free_end=True)``), constrained to the solid side; its rows also
      move with the end vertex's rows. It gives every sample its own hidden surface, which
      the sampler must fit to every contact near the end (slow, and it kept an infeasible
      sloper truth from giving up in the measurements of docs/perception.md).
    Either way the tail is no measured surface: ``build_prior`` marks its edges as the
    shape's ``closure_edges``, which the planner never docks on.
    """
    n, m = len(verts), basis.shape[1]
    A = basis.reshape(n, 2, m)
    if occlusion.tail_model == "ray":
        rays = verts[[0, -1]] - camera_xy
        far = verts[[0, -1]] + occlusion.tail_m * rays / np.linalg.norm(rays, axis=1, keepdims=True)
        rows = np.concatenate([A[:1], A, A[-1:]])
        return np.vstack([far[:1], verts, far[1:]]), rows.reshape(2 * (n + 2), m)
    k = max(2, round(occlusion.tail_m / spacing_m))
    tails = []
    for end, side in ((0, -1.0), (n - 1, 1.0)):  # the solid is left of the walking direction
        ray = verts[end] - camera_xy
        far = verts[end] + occlusion.tail_m * ray / max(np.linalg.norm(ray), 1e-12)
        tails.append(_bridge(verts[end], far, k, occlusion, rng, sampler, free_end=True, side=side))
    (first, first_cols), (last, last_cols) = tails
    r1, r2 = first_cols.shape[1], last_cols.shape[1]
    out = np.zeros((n + 2 * k, 2, m + r1 + r2))
    out[k : k + n, :, :m] = A
    out[:k, :, :m] = A[0]
    out[k + n :, :, :m] = A[-1]
    out[:k, :, m : m + r1] = first_cols.reshape(k, 2, r1)[::-1]  # walking order: far to near
    out[k + n :, :, m + r1 :] = last_cols.reshape(k, 2, r2)
    return np.vstack([first[::-1], verts, last]), out.reshape(2 * (n + 2 * k), -1)


def _bridge(a, b, k: int, occlusion: OcclusionParams, rng, sampler: Sampler, **kwargs):
    """``occlusion_columns`` with the configured bridge diffusion and sample counts."""
    return occlusion_columns(
        a,
        b,
        k,
        occlusion.bridge_sigma_m_per_sqrt_m,
        occlusion.columns,
        occlusion.samples,
        occlusion.trajectories,
        rng,
        sampler,
        **kwargs,
    )


def build_prior(
    terrain: TerrainSlice,
    extrinsic: Extrinsic,
    noise: DepthNoise,
    occlusion: OcclusionParams,
    friction: float,
    rng: np.random.Generator,
    sampler: Sampler = sample_truncated_gaussian,
    surface: SurfaceParams | None = None,
) -> GaussianShape:
    """GaussianShape prior of a slice (columns: calibration, surface, occlusion)."""
    surface = surface or SurfaceParams()
    verts, surface_block = surface_columns(terrain, extrinsic, noise, surface)
    if surface.depth_model == "independent":
        calibration = calibration_columns(verts, extrinsic)
    else:
        shift, calibration = calibration_transform(verts, extrinsic)
        verts = verts + shift
    n = len(verts)
    blocks = []
    for first, last in terrain.stretches:
        k = last - first - 1
        mean, basis = _bridge(verts[first], verts[last], k, occlusion, rng, sampler)
        verts[first + 1 : last] = mean
        block = np.zeros((2 * n, basis.shape[1]))
        block[2 * (first + 1) : 2 * last] = basis
        blocks.append(block)
    basis = np.hstack(
        [
            calibration,
            surface_block,
            *blocks,
        ]
    )
    closure: tuple[int, ...] = ()
    if occlusion.tail_m > 0:
        verts, basis = add_tails(
            verts, basis, terrain.camera_xy, occlusion, terrain.spacing_m, rng, sampler
        )
        t = (len(verts) - n) // 2  # tail vertices per end: the first and last t edges
        closure = (*range(t), *range(t + n - 1, 2 * t + n - 1))
    return GaussianShape(
        verts.ravel(), basis, closed=False, friction=friction, closure_edges=closure
    )


@dataclass(frozen=True)
class Perception:
    """Result of ``perceive``: the slice it was built from and the prior."""

    slice: TerrainSlice
    prior: GaussianShape

    @property
    def hidden(self) -> np.ndarray:
        """(prior.n_vertices,) bool: hidden prior vertices (stretches and the two tails)."""
        k = (self.prior.n_vertices - len(self.slice.hidden)) // 2
        return np.r_[np.ones(k, bool), self.slice.hidden, np.ones(k, bool)]


def perceive(
    depth_m: np.ndarray, K: np.ndarray, config: PerceptionConfig, rng: np.random.Generator
) -> Perception:
    """Depth image in metres (NaN invalid, e.g. from ``depth.decode_depth``) -> slice and prior.

    Raises ``PerceptionError`` (a ValueError) when the image cannot give a prior.
    """
    depth = np.asarray(depth_m, float)
    noise = config.depth_noise
    depth = np.where((depth >= noise.min_range_m) & (depth <= noise.max_range_m), depth, np.nan)
    terrain = extract_slice(
        depth, K, config.extrinsic, config.slice, config.occlusion.max_hidden_vertices
    )
    prior = build_prior(
        terrain,
        config.extrinsic,
        noise,
        config.occlusion,
        config.friction,
        rng,
        surface=config.surface,
    )
    return Perception(terrain, prior)
