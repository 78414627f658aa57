"""The robot's prior from one depth image: the learned terrain prior where the library explains
the image, the generic depth prior where it does not (the out-of-library gate).

``learned_prior.condition`` always returns its best class, even for a wall no class resembles;
its Gaussian would then be confidently wrong. The gate keeps the learned prior only when the
best class explains at least ``min_inlier_fraction`` of the slice bins (``ClassFit.inliers``:
residual within ``learned_prior.GATE`` stds); otherwise ``terrain_prior.perceive`` builds the
generic prior (paper Sec. III-A1) from the same image.

Decision (the threshold, :func:`fit_threshold`): measured on training scans only. In-library
scans are training truths rendered by the camera and conditioned on the whole library;
out-of-library scans are the same images conditioned on the library without the truth's class
(the nearest wall the library does not know). The threshold is the midpoint between the
in-library 1 % quantile and the out-of-library 99 % quantile of the best class's inlier
fraction; where they overlap (no clean separation) or there is no second class, it is the
in-library 1 % quantile minus ``SINGLE_CLASS_MARGIN``, so at most ~1 % of in-library images
fall back (the generic prior is the safe side).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..core.shape import GaussianShape
from .config import PerceptionConfig
from .learned_prior import LearnedPrior, SliceRays, TerrainLibrary, condition, condition_rays
from .terrain_prior import perceive

IN_LIBRARY_QUANTILE = 0.01
OUT_OF_LIBRARY_QUANTILE = 0.99
SINGLE_CLASS_MARGIN = 0.02


@dataclass(frozen=True)
class SelectedPrior:
    """Result of :func:`select_prior`.

    Attributes:
        prior: the prior to publish.
        model: ``"learned"`` or ``"generic"`` (the gate fell back).
        learned: every class's fit (also when the gate fell back: it says why).
        min_inlier_fraction: the threshold applied.
        reason: one line for the log and the status.
    """

    prior: GaussianShape
    model: str
    learned: LearnedPrior
    min_inlier_fraction: float
    reason: str

    @property
    def class_name(self) -> str:
        """The learned class used ('' when the generic prior was)."""
        return self.learned.name if self.model == "learned" else ""


def gate_threshold(library: TerrainLibrary, min_inlier_fraction: float | None) -> float:
    """The threshold to apply: ``min_inlier_fraction`` when given, else the library's.

    Raises ValueError when neither is set or the value is outside [0, 1]."""
    gate = library.min_inlier_fraction if min_inlier_fraction is None else min_inlier_fraction
    if gate is None:
        raise ValueError(
            "the terrain class library has no fitted min_inlier_fraction (format 1): give one "
            "or refit it with tools.fit_terrain_classes"
        )
    if not (np.isfinite(gate) and 0.0 <= gate <= 1.0):
        raise ValueError(f"min_inlier_fraction must be in [0, 1], got {gate}")
    return float(gate)


def select_prior(
    depth: np.ndarray,
    K: np.ndarray,
    config: PerceptionConfig,
    library: TerrainLibrary,
    rng: np.random.Generator,
    min_inlier_fraction: float | None = None,
) -> SelectedPrior:
    """The learned prior of ``depth`` if its best class passes the gate, else the generic one
    (``rng`` is used only then, by the occlusion sampler). Raises ``PerceptionError`` when the
    image gives no slice, ValueError when no threshold is known (:func:`gate_threshold`)."""
    gate = gate_threshold(library, min_inlier_fraction)
    fit = condition(library, depth, K, config)
    share = fit.inlier_fraction
    if share >= gate:
        reason = f"class {fit.name}: {share:.3f} of the slice explained (gate {gate:.3f})"
        return SelectedPrior(fit.prior, "learned", fit, gate, reason)
    reason = (
        f"out of library: the best class {fit.name} explains {share:.3f} of the slice "
        f"(gate {gate:.3f}); generic depth prior"
    )
    return SelectedPrior(perceive(depth, K, config, rng).prior, "generic", fit, gate, reason)


def inlier_samples(
    library: TerrainLibrary, scans: Sequence[tuple[SliceRays, str]], config: PerceptionConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The best class's inlier fraction per scan ``(rays, its class name)`` with the whole
    library (in library) and with the library without that class (out of library; empty for a
    one-class library): the two samples :func:`fit_threshold` takes."""
    inside, outside = [], []
    for rays, name in scans:
        inside.append(condition_rays(library, rays, config).inlier_fraction)
        others = tuple(c for c in library.classes if c.name != name)
        if others:
            outside.append(condition_rays(TerrainLibrary(others), rays, config).inlier_fraction)
    return np.array(inside), np.array(outside)


def fit_threshold(in_library: np.ndarray, out_of_library: np.ndarray) -> float:
    """The gate from inlier fractions of training scans (see the module docstring)."""
    inside = np.asarray(in_library, float)
    outside = np.asarray(out_of_library, float)
    if inside.size == 0 or not np.all(np.isfinite(inside)):
        raise ValueError("need finite in-library inlier fractions")
    low = float(np.quantile(inside, IN_LIBRARY_QUANTILE))
    if outside.size:
        high = float(np.quantile(outside, OUT_OF_LIBRARY_QUANTILE))
        if high < low:
            return 0.5 * (low + high)
    return max(0.0, low - SINGLE_CLASS_MARGIN)
