"""Synthetic terrains and a default camera for tests, the benchmark and mock hardware.

Plane frame: x out of the wall, y up, z along the plane normal (metres). The wall's solid is at
x < 0 and profiles run bottom to top, so the solid is on the left (``core.shape`` orientation).
The camera sits below and in front of the holds, looking up at them as a climber does, so
ledge tops and pockets are hidden.
"""

from __future__ import annotations

import numpy as np

WALL_BOTTOM_M = -0.6
WALL_TOP_M = 1.0


def look_at_pose(camera: np.ndarray, target: np.ndarray) -> np.ndarray:
    """4x4 camera optical frame -> plane frame: optical axis toward the in-plane ``target``.

    Image x points along -z_plane and image y 'down' within the plane, so the docking plane is
    (near) the image column through the principal point.
    """
    camera = np.asarray(camera, float)
    axis = np.r_[np.asarray(target, float), 0.0] - camera
    axis[2] = 0.0
    z_cam = axis / np.linalg.norm(axis)
    x_cam = np.array([0.0, 0.0, -1.0])
    y_cam = np.cross(z_cam, x_cam)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x_cam, y_cam, z_cam])
    T[:3, 3] = camera
    return T


def default_camera(width: int = 640, height: int = 480, offset_z_m: float = 0.03):
    """(K, T_plane_camera): 525 px focal length at 640 px width (scaled with it), 0.7 m out from
    the wall and 0.1 m below the holds, ``offset_z_m`` off the plane."""
    f = 525.0 * width / 640
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0, 0, 1]])
    return K, look_at_pose(np.array([0.7, -0.1, offset_z_m]), np.array([0.0, 0.28]))


def _wall(points: list[tuple[float, float]]) -> np.ndarray:
    """Close a feature list with the wall below and above it."""
    return np.array([(points[0][0], WALL_BOTTOM_M), *points, (points[-1][0], WALL_TOP_M)])


def ledges() -> np.ndarray:
    """Two ledges whose flat tops are hidden from below."""
    return _wall(
        [(0.0, 0.0), (0.07, 0.04), (0.07, 0.08), (0.0, 0.08), (0.0, 0.3), (0.05, 0.33),
         (0.05, 0.36), (0.0, 0.36)]
    )  # fmt: skip


def notch() -> np.ndarray:
    """A notch cut down into the wall: its lower face is hidden, its upper face seen."""
    return _wall([(0.0, 0.2), (-0.05, 0.15), (0.0, 0.26)])


def pocket_behind_lip() -> np.ndarray:
    """A ledge with a raised lip at its front; the pocket behind the lip is hidden."""
    return _wall([(0.0, 0.2), (0.08, 0.2), (0.08, 0.27), (0.065, 0.27), (0.065, 0.23), (0.0, 0.23)])


def random_terrain(rng: np.random.Generator) -> np.ndarray:
    """A wall with 1-3 random ledges, notches or slopes between y = 0 and 0.6 m."""
    points: list[tuple[float, float]] = [(0.0, 0.0)]
    y, x = 0.0, 0.0
    for _ in range(rng.integers(1, 4)):
        step = rng.uniform(0.04, 0.1)
        y += step
        kind = rng.integers(3)
        depth, height = rng.uniform(0.03, 0.08), rng.uniform(0.02, 0.06)
        if kind == 0:  # ledge: sloped underside, front face, hidden top
            points += [(x, y), (x + depth, y + rng.uniform(0.0, 0.04))]
            y = points[-1][1] + height
            points += [(x + depth, y), (x, y)]
        elif kind == 1:  # notch cut down into the wall, no lower than the previous feature
            drop = min(height, step - 0.01)
            points += [(x, y), (x - depth, y - drop)]
            y += height
            points += [(x, y)]
        else:  # the wall steps out or in along a slope
            x_new = x + rng.uniform(-0.04, 0.04)
            y += height
            points += [(x, y - height), (x_new, y)]
            x = x_new
    points.append((x, y + 0.05))
    return _wall(points)


TERRAINS = {"ledges": ledges, "notch": notch, "pocket_behind_lip": pocket_behind_lip}
