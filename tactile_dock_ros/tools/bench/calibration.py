"""How honest predicted probabilities are: expected calibration error, Spiegelhalter's test,
reliability diagrams.

Used on the P_dock of executed docking attempts (``bench docking``): each attempt predicted
p in [0, 1] and docked (1) or not (0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ECE_BINS = 10  # equal-width bins of the predicted probability


def _probabilities(predicted) -> np.ndarray:
    p = np.asarray(predicted, float)
    if p.ndim != 1 or not len(p):
        raise ValueError("predicted must be a non-empty 1-D array")
    if np.any(~np.isfinite(p)) or np.any((p < 0) | (p > 1)):
        raise ValueError("predicted probabilities must lie in [0, 1]")
    return p


def _checked(predicted, outcome) -> tuple[np.ndarray, np.ndarray]:
    p, y = np.asarray(predicted, float), np.asarray(outcome, float)
    if p.ndim != 1 or p.shape != y.shape or not len(p):
        raise ValueError("predicted and outcome must be non-empty 1-D arrays of one length")
    _probabilities(p)
    if np.any((y != 0) & (y != 1)):
        raise ValueError("outcomes must be 0 or 1")
    return p, y


def equal_bins(predicted, bins: int = ECE_BINS) -> np.ndarray:
    """Bin index (k,) of each prediction in ``bins`` equal bins of [0, 1] (1 in the last)."""
    return np.minimum((np.asarray(predicted, float) * bins).astype(int), bins - 1)


def expected_calibration_error(predicted, outcome, bins: int = ECE_BINS) -> float:
    """ECE: sum over equal bins of (attempts in bin / attempts) x |mean predicted - observed
    frequency| (Naeini et al. 2015). A calibrated predictor scores above 0 by chance, about
    0.02-0.03 at 1,000 attempts."""
    p, y = _checked(predicted, outcome)
    which = equal_bins(p, bins)
    counts = np.bincount(which, minlength=bins)
    gap = np.abs(np.bincount(which, p, bins) - np.bincount(which, y, bins))
    return float(gap.sum() / counts.sum())


def spiegelhalter_z(predicted, outcome) -> float:
    """Spiegelhalter's (1986) z statistic of the Brier score: standard normal when the outcomes
    are Bernoulli(predicted); |z| > 1.96 rejects calibration at 5 %. 0 when every prediction
    is 0 or 1 (no variance: the test says nothing)."""
    p, y = _checked(predicted, outcome)
    variance = np.sum((1 - 2 * p) ** 2 * p * (1 - p))
    if variance <= 0:
        return 0.0
    return float(np.sum((y - p) * (1 - 2 * p)) / np.sqrt(variance))


def clustered_spiegelhalter_z(predicted, outcome, groups) -> float:
    """Spiegelhalter's z for attempts that come in dependent groups, e.g. all episodes on one
    ground truth (``groups``: one label per attempt; the groups must be independent, the
    attempts within one need not be).

    ``spiegelhalter_z`` assumes independent attempts. ``bench docking --episode-seeds K`` runs
    each truth K times with other sampler seeds, and the first attempts are near copies: the
    same prior, a prediction that differs by sampling noise only, the same truth and so, almost
    always, the same outcome. K copies scale that z by sqrt(K): on 2026-11-28 (commit 9e3d3f4,
    learned prior, test split, 40 truths x 9 seeds) z was -3.40 / -4.42 (compliant /
    non-compliant) while each seed's 120 episodes alone gave |z| <= 1.75 (mean -1.1 / -1.5)
    and the first attempts of one truth docked alike on 109 / 108 of 111 truths; this z,
    grouped by truth, gave -1.27 / -1.81.

    Decision: the numerator is the classic one, sum (y - p)(1 - 2p); its variance is the
    cluster-robust (Liang-Zeger) sum over groups of each group's squared sum, which needs no
    model of the dependence within a group. Exact copies within groups leave z unchanged. Like
    any sandwich variance it needs many groups (tens); with one attempt per group it is the
    classic z with the observed instead of the predicted variance, close to it when
    calibrated. 0 when the variance is 0.
    """
    p, y = _checked(predicted, outcome)
    labels = np.asarray(groups)
    if labels.shape != p.shape:
        raise ValueError("groups must give one label per attempt")
    _, which = np.unique(labels, return_inverse=True)
    sums = np.bincount(which.ravel(), (y - p) * (1 - 2 * p))
    variance = np.sum(sums**2)
    if variance <= 0:
        return 0.0
    return float(sums.sum() / np.sqrt(variance))


def calibrated_ece(
    predicted, clusters, rng: np.random.Generator, draws: int = 1000, bins: int = ECE_BINS
) -> np.ndarray:
    """(draws,) the ECE a perfectly calibrated predictor scores on these attempts: outcomes
    drawn with P(dock) = ``predicted``, one uniform per cluster (``clusters``: one label per
    attempt) shared by its attempts, an attempt docking when the uniform is below its
    prediction. Compare a measured ECE with this distribution's upper percentiles.

    Decision: ``bench docking --episode-seeds K`` runs each truth K times; the same attempt
    (first, second, ...) of one truth is a near copy in every episode (the same image, a
    prediction that differs by sampling noise, the same truth, so almost always the same
    outcome: ``clustered_spiegelhalter_z``). Its clusters are (truth, attempt number), fully
    dependent within (the shared uniform), independent between. The floor then depends on the
    number of clusters, not of attempts: at 1,000 independent attempts a calibrated predictor
    scores ~0.02 (95th percentile ~0.027); on 40 truths x 9 seeds (~1,200 attempts in ~140
    clusters, 2026-11-29) its median was 0.040-0.052 and its 95th percentile 0.060-0.074."""
    p = _probabilities(predicted)
    labels = np.asarray(clusters)
    if labels.shape != p.shape:
        raise ValueError("clusters must give one label per attempt")
    if draws < 1:
        raise ValueError(f"draws must be >= 1, got {draws}")
    _, which = np.unique(labels, return_inverse=True)
    which = which.ravel()
    out = np.empty(draws)
    for d in range(draws):  # one ECE per draw: a handful of bincounts
        docked = rng.random(int(which.max()) + 1)[which] < p
        out[d] = expected_calibration_error(p, docked.astype(float), bins)
    return out


def reliability_png(path: Path, title: str, series: dict[str, tuple], bins: int = ECE_BINS):
    """A reliability diagram: per series (name -> (predicted, outcome)), the observed docked
    fraction against the mean prediction of each non-empty equal bin, marker area by attempts,
    with the diagonal of perfect calibration; the legend gives each series' ECE."""
    from .. import figures

    plt = figures.pyplot()
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--")
    for name, (predicted, outcome) in series.items():
        p, y = _checked(predicted, outcome)
        which = equal_bins(p, bins)
        counts = np.bincount(which, minlength=bins)
        used = counts > 0
        mean_p = np.bincount(which, p, bins)[used] / counts[used]
        freq = np.bincount(which, y, bins)[used] / counts[used]
        ece = expected_calibration_error(p, y, bins)
        (line,) = ax.plot(mean_p, freq, "-", lw=1, label=f"{name}: ECE {ece:.3f} ({len(p)})")
        ax.scatter(mean_p, freq, s=8 + 60 * counts[used] / counts.max(), color=line.get_color())
    ax.set(xlim=(0, 1), ylim=(0, 1), xlabel="predicted P_dock", ylabel="docked fraction")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    figures.save(fig, path)
