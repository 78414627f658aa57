"""The robot's prior from one depth image: the learned terrain prior where the library explains
the image, the generic depth prior where it does not (the out-of-library gate).

``learned_prior.condition`` always returns its best class, even for a wall no class resembles;
its Gaussian would then be confidently wrong. The gate keeps the learned prior only when the
best class explains at least that class's ``min_inlier_fraction`` of the slice bins
(``ClassFit.inlier_fraction``: residual within ``learned_prior.GATE`` stds, bins at a depth
step not counted); otherwise ``terrain_prior.perceive`` builds the generic prior (paper Sec.
III-A1) from the same image.

Decision (the thresholds, :func:`fit_thresholds`): measured on training scans only, one per
class. In-library scans are training truths rendered by the camera and conditioned on the whole
library; out-of-library scans are the same images conditioned on the library without the
truth's class (the nearest wall the library does not know). Both are grouped by the class that
explains them best, the class whose gate decides. A class's threshold is the midpoint between
its in-library 1 % quantile and its out-of-library 99 % quantile of the inlier fraction; where
they overlap (no clean separation) or no out-of-library scan chose the class, it is the
in-library 1 % quantile minus ``SINGLE_CLASS_MARGIN``, so ~1 % of each class's images fall back
(the generic prior is the safe side). Why per class (measured on 300 train scans per class,
docs/perception.md): the classes' tails differ (in-library 1 % quantiles sloper 0.987, notch
0.972, three_ledges 0.991), and where one class's out-of-library scans reach its own tail a
pooled threshold is either loose for the others or sends that class's images to the generic
prior.

Names (perception's ``prior_source``, ``bench docking --prior``): ``depth`` is this selection,
the robot's camera prior; ``generic`` is the generic depth prior alone (no terrain model: its
P_dock are overconfident, docs/benchmarks.md); ``learned`` is accepted as the earlier name of
``depth``.
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
PRIOR_SOURCES = ("depth", "generic", "problem")  # problem: a benchmark problem's hand-made prior
SOURCE_ALIASES = {"learned": "depth"}  # earlier names


def prior_source(name: str) -> str:
    """``name`` with an earlier name (``SOURCE_ALIASES``) replaced by the current one."""
    return SOURCE_ALIASES.get(name, name)


@dataclass(frozen=True)
class SelectedPrior:
    """Result of :func:`select_prior`.

    Attributes:
        prior: the prior to publish.
        model: ``"learned"`` or ``"generic"`` (the gate fell back).
        learned: every class's fit (also when the gate fell back: it says why).
        min_inlier_fraction: the threshold applied (the best class's).
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


def gate_thresholds(library: TerrainLibrary, min_inlier_fraction: float | None) -> dict[str, float]:
    """The threshold per class: ``min_inlier_fraction`` for every class when given, else each
    class's own.

    Raises ValueError when a class has neither or the value is outside [0, 1]."""
    if min_inlier_fraction is not None:
        if not (np.isfinite(min_inlier_fraction) and 0.0 <= min_inlier_fraction <= 1.0):
            raise ValueError(f"min_inlier_fraction must be in [0, 1], got {min_inlier_fraction}")
        return {name: float(min_inlier_fraction) for name in library.names}
    missing = [name for name, gate in library.gates.items() if gate is None]
    if missing:
        raise ValueError(
            f"the terrain class library has no fitted min_inlier_fraction for {missing} "
            "(a format 1 file, or classes fitted without gates): give one or refit it with "
            "tools.fit_terrain_classes"
        )
    return {name: float(gate) for name, gate in library.gates.items()}


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
    image gives no slice, ValueError when no threshold is known (:func:`gate_thresholds`)."""
    gates = gate_thresholds(library, min_inlier_fraction)
    fit = condition(library, depth, K, config)
    gate, share = gates[fit.name], fit.inlier_fraction
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
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The best class's inlier fraction per scan ``(rays, its class name)`` with the whole
    library (in library) and with the library without that class (out of library; none for a
    one-class library), each grouped by the best class's name (every class has an entry, maybe
    empty): the two samples :func:`fit_thresholds` takes."""
    inside: dict[str, list[float]] = {name: [] for name in library.names}
    outside: dict[str, list[float]] = {name: [] for name in library.names}
    for rays, name in scans:
        fit = condition_rays(library, rays, config)
        inside[fit.name].append(fit.inlier_fraction)
        if len(library.classes) > 1:
            fit = condition_rays(library.without(name), rays, config)
            outside[fit.name].append(fit.inlier_fraction)
    return _arrays(inside), _arrays(outside)


def _arrays(groups: dict[str, list[float]]) -> dict[str, np.ndarray]:
    return {name: np.array(values) for name, values in groups.items()}


def fit_thresholds(
    in_library: dict[str, np.ndarray], out_of_library: dict[str, np.ndarray]
) -> dict[str, float]:
    """Each class's gate from :func:`inlier_samples` (see the module docstring); a class no
    in-library scan chose gets the threshold of all classes' samples pooled. Raises ValueError
    when there is no in-library scan at all."""
    pooled = fit_threshold(
        np.concatenate([np.ravel(v) for v in in_library.values()] or [[]]),
        np.concatenate([np.ravel(v) for v in out_of_library.values()] or [[]]),
    )
    return {
        name: fit_threshold(inside, out_of_library.get(name, [])) if np.size(inside) else pooled
        for name, inside in in_library.items()
    }


def fit_threshold(in_library: np.ndarray, out_of_library: np.ndarray) -> float:
    """One class's gate from inlier fractions of training scans (see the module docstring)."""
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
