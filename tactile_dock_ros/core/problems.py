"""Benchmark docking problems in the spirit of the paper's figures (Sec. IV-F, V-A3, VI-A).

Every problem is a terrain profile in a vertical plane (x right, y up, metres) with the solid
below the profile, so vertices run right to left (CCW around the solid, see ``core.shape``). The
camera sits below and to the right of the holds, as for a climber looking up: faces turned away
from it (the tops of the ledges) are hidden and carry extra smooth shape uncertainty.

``load`` is the unit direction in which the robot pushes on the hold during the loading move
(the paper's f_load); docking succeeds where friction cancels it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import prior as prior_columns
from .shape import GaussianShape


@dataclass(frozen=True)
class Problem:
    """A docking problem: prior over the terrain, load, friction and where the tool starts."""

    name: str
    prior: GaussianShape
    load: np.ndarray  # (2,) unit vector
    friction: float
    start: np.ndarray  # (2,) metres
    contact_resolution: float  # metres: the exploration-bonus width w of eq. (24)
    sensor: np.ndarray  # (2,) camera position in the plane, metres
    hidden: np.ndarray  # (n,) bool: vertices the camera cannot see

    def sample_ground_truth(self, rng: np.random.Generator) -> np.ndarray:
        """One terrain drawn from the prior: (n, 2) vertices."""
        return self.prior.vertices(self.prior.sample_z(rng, 1))[0]


@dataclass(frozen=True)
class _Spec:
    """Terrain outline (left to right) and the uncertainty model applied to it."""

    outline: list[tuple[float, float]]
    n_vertices: int
    load: tuple[float, float]
    friction: float
    start: tuple[float, float]
    sensor: tuple[float, float]
    sigma_xy: float = 0.01  # localization, metres
    sigma_theta: float = np.deg2rad(1.0)  # localization about the sensor, radians
    sigma_depth: float = 0.002  # per-vertex depth noise along the ray, metres
    sigma_hidden: float = 0.015  # smooth deviation of hidden stretches, metres
    hidden_length: float = 0.04  # its correlation length, metres
    hidden_columns: int = 8
    contact_resolution: float = 0.01


def _resample(outline: np.ndarray, count: int) -> np.ndarray:
    """Subdivide each outline segment in proportion to its length; keeps every corner."""
    seg_len = np.linalg.norm(np.diff(outline, axis=0), axis=1)
    extra = count - len(outline)
    pieces = np.ones(len(seg_len), dtype=int)
    if extra > 0:
        share = seg_len / seg_len.sum() * extra
        pieces += np.floor(share).astype(int)
        remainder = extra - (pieces.sum() - len(seg_len))
        pieces[np.argsort(share - np.floor(share))[::-1][:remainder]] += 1
    points = [
        p + np.outer(np.arange(k) / k, q - p)
        for p, q, k in zip(outline[:-1], outline[1:], pieces, strict=True)
    ]
    return np.vstack([*points, outline[-1:]])


def _build(name: str, spec: _Spec) -> Problem:
    verts = _resample(np.array(spec.outline[::-1], float), spec.n_vertices)
    sensor = np.array(spec.sensor, float)
    normals = prior_columns.vertex_normals(verts)
    hidden = np.einsum("ij,ij->i", normals, sensor - verts) <= 0.0
    basis = np.hstack(
        [
            prior_columns.translation_columns(len(verts), spec.sigma_xy, spec.sigma_xy),
            prior_columns.rotation_column(verts, sensor, spec.sigma_theta),
            prior_columns.ray_columns(verts, sensor, np.full(len(verts), spec.sigma_depth)),
            prior_columns.smooth_normal_columns(
                verts, hidden, spec.sigma_hidden, spec.hidden_length, spec.hidden_columns
            ),
        ]
    )
    load = np.array(spec.load, float)
    return Problem(
        name=name,
        prior=GaussianShape(verts.ravel(), basis, closed=False, friction=spec.friction),
        load=load / np.linalg.norm(load),
        friction=spec.friction,
        start=np.array(spec.start, float),
        contact_resolution=spec.contact_resolution,
        sensor=sensor,
        hidden=hidden,
    )


NOTCH_SIGMA = 0.012
NOTCH_SLOPE = 0.5


def _sloper() -> Problem:
    """Two rounded sloping holds, one above the other, near the friction angle (Figs. 2, 8).

    Each hold's top slopes outward at about atan(mu) and rounds over into an overhanging lip, so
    a slide on one hold falls off its lip and never reaches the other. The tops are hidden from
    the camera: smooth deviations (12 mm, 15 cm) tilt each top by a few degrees independently
    and the rotation (3 degrees) tilts both. Whether a hold holds, and which, is uncertain:
    about half the truths have no feasible docking site.
    """
    mu = 0.5
    return _build(
        "sloper",
        _Spec(
            outline=[
                (-0.35, -0.05),
                (-0.35, 0.2),
                (-0.05, 0.2 - 0.30 * 0.63),  # upper hold: top at ~29 degrees
                (-0.02, 0.2 - 0.30 * 0.63 - 0.04),  # rounded lip
                (-0.06, -0.05),  # overhanging riser
                (0.30, -0.05 - 0.36 * 0.61),  # lower hold
                (0.33, -0.05 - 0.36 * 0.61 - 0.04),
                (0.30, -0.35),
            ],
            n_vertices=12,
            load=(0.0, -1.0),
            friction=mu,
            start=(0.0, 0.45),
            sensor=(0.8, -0.6),
            sigma_theta=np.deg2rad(3.0),
            sigma_depth=0.0005,
            sigma_hidden=0.013,
            hidden_length=0.15,
        ),
    )


def _slab_outline(top: tuple[float, float], slab: float, notch: float) -> list[tuple[float, float]]:
    """Two slabs falling at slope ``slab`` (dy/dx) from ``top``, each with a 4 cm notch piece
    of slope ``notch`` 13 cm along it, a lip 12 cm further and an overhanging 8 cm riser."""
    x, y = top
    points = [(x, y - 0.25), (x, y)]
    for _ in range(2):
        for dx, slope in ((0.13, slab), (0.04, notch), (0.12, slab)):
            x, y = x + dx, y - dx * slope
            points.append((round(x, 4), round(y, 4)))
        x, y = x - 0.03, y - 0.08  # overhanging riser: a slide falls off the lip
        points.append((round(x, 4), round(y, 4)))
    points[-1] = (points[-2][0], points[-2][1] - 0.15)
    return points


def _notch() -> Problem:
    """Two slabs too steep to hold, each with a small hidden notch that can trap the tool.

    The slabs fall at 45 degrees (mu = 0.5 holds up to 26.6) and end in overhanging lips, so a
    slide falls off and never reaches the other slab. A third of the way down each slab a 4 cm
    notch piece, flatter than the friction angle in the mean, can stop a sliding tool, but it
    is hidden from the camera: smooth deviations (``NOTCH_SIGMA``, 3 cm) make its tilt and
    position uncertain, and in many truths one notch (sometimes both) is too steep to hold.
    """
    return _build(
        "notch",
        _Spec(
            outline=_slab_outline((-0.35, 0.25), 1.0, NOTCH_SLOPE),
            n_vertices=24,
            load=(0.0, -1.0),
            friction=0.5,
            start=(0.0, 0.45),
            sensor=(0.8, -0.9),
            sigma_depth=0.0005,
            sigma_hidden=NOTCH_SIGMA,
            hidden_length=0.03,
        ),
    )


def _three_ledges() -> Problem:
    """Three ledges on a wall (Fig. 11): 82 vertices, 81 edges, hidden ledge tops.

    Every top slopes outward at 30 degrees, just beyond the friction angle (26.6 degrees for
    mu = 0.5), and its shape is hidden from the camera: smooth deviations (8 mm, 6 cm) tilt
    single edges by several degrees, so whether and where a top holds is uncertain. The risers
    overhang slightly, so the valleys at their feet are out of reach of a straight push.
    """
    return _build(
        "three_ledges",
        _Spec(
            outline=[
                (-0.6, -0.45),
                (-0.6, 0.5),
                (-0.4, 0.385),  # ledge 1 lip
                (-0.42, 0.26),
                (-0.2, 0.133),  # ledge 2 lip
                (-0.22, 0.05),
                (0.0, -0.077),  # ledge 3 lip
                (-0.02, -0.15),
                (0.3, -0.335),
                (0.3, -0.45),
            ],
            n_vertices=82,
            load=(0.0, -1.0),
            friction=0.5,
            start=(0.2, 0.7),
            sensor=(0.9, -0.8),
            sigma_hidden=0.008,
            hidden_length=0.06,
        ),
    )


_REGISTRY: dict[str, Callable[[], Problem]] = {
    "sloper": _sloper,
    "notch": _notch,
    "three_ledges": _three_ledges,
}


def names() -> list[str]:
    """Problem names accepted by ``get``."""
    return list(_REGISTRY)


def get(name: str) -> Problem:
    """The named problem; ValueError lists the valid names."""
    try:
        return _REGISTRY[name]()
    except KeyError:
        raise ValueError(f"unknown problem {name!r}; choose from {names()}") from None
