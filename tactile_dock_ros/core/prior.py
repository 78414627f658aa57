"""Columns of the prior basis A (paper Sec. III-A1).

Each function returns a (2n, k) block of independent deviations from the mean shape; a prior is
``GaussianShape(mean, np.hstack(blocks))``. Vertices are (n, 2) arrays in the plane frame, the
sensor is the camera's position in that plane.
"""

from __future__ import annotations

import numpy as np

from .geometry2d import outward_normal, perp


def translation_columns(n: int, sigma_x: float, sigma_y: float) -> np.ndarray:
    """Localization error in translation: every vertex shifts alike. (2n, 2)."""
    cols = np.zeros((2 * n, 2))
    cols[0::2, 0] = sigma_x
    cols[1::2, 1] = sigma_y
    return cols


def rotation_column(vertices: np.ndarray, sensor: np.ndarray, sigma_theta: float) -> np.ndarray:
    """Small-angle rotation about the sensor, sigma_theta radians: sigma * (-dy, dx). (2n, 1)."""
    d = np.asarray(vertices, float) - np.asarray(sensor, float)
    return sigma_theta * perp(d).reshape(-1, 1)


def ray_columns(vertices: np.ndarray, sensor: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Independent depth noise of each vertex along its viewing ray, sigma (n,) metres. (2n, n)."""
    d = np.asarray(vertices, float) - np.asarray(sensor, float)
    rays = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    n = len(d)
    cols = np.zeros((2 * n, n))
    idx = np.arange(n)
    sigma = np.broadcast_to(np.asarray(sigma, float), (n,))
    cols[2 * idx, idx] = sigma * rays[:, 0]
    cols[2 * idx + 1, idx] = sigma * rays[:, 1]
    return cols


def vertex_normals(vertices: np.ndarray) -> np.ndarray:
    """Unit outward normals at the vertices of an open CCW polyline (right of travel). (n, 2)."""
    v = np.asarray(vertices, float)
    tangent = np.gradient(v, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    return outward_normal(tangent)


def smooth_normal_columns(
    vertices: np.ndarray,
    mask: np.ndarray,
    sigma: float,
    length_scale: float,
    count: int,
) -> np.ndarray:
    """Smooth shape deviations along the vertex normals on the masked vertices. (2n, count).

    A squared-exponential Gaussian process over arc length (std ``sigma`` metres, correlation
    length ``length_scale`` metres), truncated to its ``count`` leading eigenvectors. Used for
    uncertain stretches of synthetic problems; perception builds its occlusion columns from the
    constrained Brownian bridge instead.
    """
    v = np.asarray(vertices, float)
    mask = np.asarray(mask, bool)
    n = len(v)
    if not mask.any() or count <= 0:
        return np.zeros((2 * n, 0))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))])[mask]
    kernel = sigma**2 * np.exp(-0.5 * ((s[:, None] - s[None, :]) / length_scale) ** 2)
    values, vectors = np.linalg.eigh(kernel)
    order = np.argsort(values)[::-1][: min(count, mask.sum())]
    amplitudes = vectors[:, order] * np.sqrt(np.clip(values[order], 0.0, None))  # (k, count)
    normals = vertex_normals(v)[mask]
    cols = np.zeros((n, 2, len(order)))
    cols[mask] = normals[:, :, None] * amplitudes[:, None, :]
    return cols.reshape(2 * n, len(order))
