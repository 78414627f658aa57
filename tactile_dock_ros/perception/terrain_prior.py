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
        mean, basis = occlusion_columns(
            verts[first],
            verts[last],
            k,
            occlusion.bridge_sigma_m_per_sqrt_m,
            occlusion.columns,
            occlusion.samples,
            occlusion.trajectories,
            rng,
            sampler,
        )
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
    return GaussianShape(verts.ravel(), basis, closed=False, friction=friction)


@dataclass(frozen=True)
class Perception:
    """Result of ``perceive``: the slice it was built from and the prior."""

    slice: TerrainSlice
    prior: GaussianShape


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
