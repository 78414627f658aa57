"""Small 2-D vector helpers in the docking plane, broadcasting over leading axes (..., 2).

Orientation as in ``core.shape``: walking an edge c -> d the solid lies on the left, so its
outward normal points right of travel.
"""

from __future__ import annotations

import numpy as np


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z of the 2-D cross product over the last axis: u_x v_y - u_y v_x (> 0: v left of u)."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def perp(v: np.ndarray) -> np.ndarray:
    """``v`` turned by +90 degrees (counter-clockwise, to its left): (x, y) -> (-y, x); so
    cross(u, v) = perp(u) . v."""
    v = np.asarray(v, float)
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def outward_normal(tangent: np.ndarray) -> np.ndarray:
    """An edge's outward normal direction, right of travel: (x, y) -> (y, -x), unnormalized."""
    t = np.asarray(tangent, float)
    return np.stack([t[..., 1], -t[..., 0]], axis=-1)


def unit(vector, name: str) -> np.ndarray:
    """Finite, non-zero 2-vector scaled to unit length; ValueError naming ``name`` otherwise."""
    v = np.asarray(vector, dtype=float).reshape(2)
    norm = float(np.hypot(*v))
    if not np.isfinite(norm) or norm <= 0.0:
        raise ValueError(f"{name} must be a finite non-zero 2-vector, got {v}")
    return v / norm
