"""Synthetic depth camera for an extruded 2-D terrain polyline (tests and mock hardware).

The terrain is the polyline swept along the plane normal (plane-frame z), over |z| <= half-width.
Because the sweep is along z, a 3-D ray hits the surface exactly where its projection onto the
plane crosses the polyline, so occlusion is exact and a pixel costs one 2-D segment test per edge.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..core.geometry2d import cross
from .config import DepthNoise
from .geometry import perturb_pose, pixel_rays


def render_depth(
    terrain_vertices: np.ndarray,
    K: np.ndarray,
    T_plane_camera: np.ndarray,
    image_size: tuple[int, int],
    rng: np.random.Generator,
    noise: DepthNoise | None = None,
    calibration_error: np.ndarray | None = None,
    half_width_m: float = np.inf,
    dropout: float = 0.0,
) -> np.ndarray:
    """Depth image (metres, float32, NaN = no return) of an extruded terrain polyline.

    Args:
        terrain_vertices: (n, 2) polyline in the plane frame, metres (any orientation).
        K: (3, 3) pinhole intrinsics (no distortion: a rectified image).
        T_plane_camera: (4, 4) NOMINAL camera optical frame -> plane frame, as in the config.
        image_size: (width, height) pixels.
        rng: source of the depth noise and dropouts.
        noise: per-pixel Gaussian depth noise sigma(z) and valid range; None = exact depths, no
            range limit.
        calibration_error: (6,) (tx, ty, tz, rx, ry, rz): the camera REALLY sits at
            ``perturb_pose(T_plane_camera, calibration_error)`` (see ``config``), while a
            consumer believes the nominal pose. None = perfectly calibrated.
        half_width_m: the extrusion spans plane z in [-half_width_m, half_width_m].
        dropout: probability that a valid pixel returns nothing.
    """
    verts = np.asarray(terrain_vertices, float)
    width, height = (int(s) for s in image_size)
    if verts.ndim != 2 or verts.shape[1] != 2 or len(verts) < 2 or not np.all(np.isfinite(verts)):
        raise ValueError("terrain_vertices must be a finite (n >= 2, 2) array")
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {image_size}")
    T = np.asarray(T_plane_camera, float)
    if calibration_error is not None:
        T = perturb_pose(T, calibration_error)
    rays = pixel_rays(np.asarray(K, float), width, height) @ T[:3, :3].T  # plane-frame, per depth
    origin = T[:3, 3]
    dxy = rays[..., :2]
    depth = np.full((height, width), np.inf)
    # One vectorized pass per edge keeps memory at O(pixels) instead of O(pixels x edges).
    for p, q in itertools.pairwise(verts):
        e = q - p
        denom = cross(dxy, e)
        w = p - origin[:2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = cross(w, e) / denom
            lam = cross(w, dxy) / denom
        hit = (
            (lam >= 0)
            & (lam <= 1)
            & (s > 0)
            & (np.abs(origin[2] + s * rays[..., 2]) <= half_width_m)
        )
        np.minimum(depth, np.where(hit, s, np.inf), out=depth)
    if noise is not None:
        finite = np.isfinite(depth)
        depth[finite] += noise.sigma(depth[finite]) * rng.standard_normal(np.count_nonzero(finite))
        depth[(depth < noise.min_range_m) | (depth > noise.max_range_m)] = np.inf
    if dropout > 0:
        depth[rng.random(depth.shape) < dropout] = np.inf
    depth[~np.isfinite(depth)] = np.nan
    return depth.astype(np.float32)
