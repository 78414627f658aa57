"""Camera rays, pose perturbations and 2-D polyline helpers shared by rendering and slicing
(2-D vector helpers: ``core.geometry2d``)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def perturb_pose(T_plane_camera: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Apply a 6-vector (tx, ty, tz, rx, ry, rz) in the config's convention to a 4x4 pose.

    Translation in metres along the plane axes; rotation vector in radians about the plane axes
    through the camera centre: R' = Exp(r) R, t' = t + tx..tz.
    """
    delta = np.asarray(delta, float).reshape(6)
    T = np.array(T_plane_camera, float)
    T[:3, :3] = Rotation.from_rotvec(delta[3:]).as_matrix() @ T[:3, :3]
    T[:3, 3] += delta[:3]
    return T


def pixel_rays(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width, 3) camera-frame rays ((u-cx)/fx, (v-cy)/fy, 1): depth times ray = point.

    Pixel centres sit at integer (u, v) as in OpenCV and ROS CameraInfo.
    """
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    v, u = np.mgrid[0:height, 0:width].astype(float)
    y = (v - cy) / fy
    x = (u - cx - skew * y) / fx
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def arc_length(points: np.ndarray) -> np.ndarray:
    """(k,) cumulative arc length of a (k, 2) polyline, starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def resample_polyline(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` >= 2 points evenly spaced in arc length along a (k, 2) polyline (ends kept)."""
    s = arc_length(points)
    if s[-1] <= 0:
        return np.repeat(points[:1], count, axis=0)
    t = np.linspace(0.0, s[-1], count)
    return np.stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])], axis=1)


def point_segment_distances(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """(k,) Euclidean distance of each point to a (n, 2) polyline."""
    p = np.asarray(points, float)[:, None, :]
    a, b = polyline[None, :-1], polyline[None, 1:]
    e = b - a
    lam = np.clip(np.sum((p - a) * e, -1) / np.maximum(np.sum(e * e, -1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + lam[..., None] * e), axis=-1).min(axis=1)
