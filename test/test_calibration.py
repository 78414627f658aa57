"""Calibration statistics of predicted probabilities (tools.bench.calibration)."""

import numpy as np
import pytest

from tactile_dock_ros.tools.bench import calibration


def test_ece_of_a_known_table():
    # bin [0.1, 0.2): 0.15 twice, docked once -> |0.15 - 0.5|; bin [0.9, 1]: 1.0 docked -> 0
    predicted = [0.15, 0.15, 1.0]
    docked = [0, 1, 1]
    assert calibration.expected_calibration_error(predicted, docked) == pytest.approx(2 / 3 * 0.35)


def test_perfect_bins_score_zero_and_a_constant_offset_scores_it():
    predicted = np.repeat([0.05, 0.55], 20)
    docked = np.concatenate([np.r_[np.ones(1), np.zeros(19)], np.r_[np.ones(11), np.zeros(9)]])
    assert calibration.expected_calibration_error(predicted, docked) == pytest.approx(0.0)
    assert calibration.expected_calibration_error(predicted + 0.3, docked) == pytest.approx(0.3)


def test_spiegelhalter_accepts_bernoulli_outcomes_and_rejects_overconfidence():
    """Over 40 seeds of 1,000 attempts drawn as Bernoulli(p): |z| <= 1.96 in about 95 % (at
    least 34 of 40 allows for chance); predictions twice the docked rate: rejected every time."""
    accepted = rejected = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        p = rng.uniform(0.0, 0.6, 1000)
        docked = (rng.random(1000) < p).astype(float)
        accepted += abs(calibration.spiegelhalter_z(p, docked)) <= 1.96
        rejected += abs(calibration.spiegelhalter_z(np.minimum(2 * p, 1.0), docked)) > 1.96
    assert accepted >= 34 and rejected == 40


def test_ece_of_calibrated_draws_is_small_and_of_overconfident_ones_large():
    rng = np.random.default_rng(7)
    p = rng.uniform(0.0, 0.6, 2000)
    docked = (rng.random(2000) < p).astype(float)
    assert calibration.expected_calibration_error(p, docked) < 0.05
    assert calibration.expected_calibration_error(np.minimum(2 * p, 1.0), docked) > 0.2


def test_certain_predictions_give_no_test():
    assert calibration.spiegelhalter_z([0.0, 1.0], [0, 1]) == 0.0


@pytest.mark.parametrize(
    "predicted, docked",
    [([], []), ([0.5], [1, 0]), ([1.5], [1]), ([np.nan], [0]), ([0.5], [2]), ([[0.5]], [[1]])],
)
def test_bad_input_is_refused(predicted, docked):
    with pytest.raises(ValueError):
        calibration.expected_calibration_error(predicted, docked)
    with pytest.raises(ValueError):
        calibration.spiegelhalter_z(predicted, docked)


def test_the_reliability_diagram_is_written(tmp_path):
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 1, 200)
    series = {"ours": (p, (rng.random(200) < p).astype(float)), "gw": (p, np.zeros(200))}
    path = tmp_path / "out" / "reliability.png"
    calibration.reliability_png(path, "test", series)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _replicated(rng, truths, copies, scale=1.0):
    """``copies`` near-identical attempts per truth (bench docking's episode seeds): a shared
    prediction plus sampling noise, one shared outcome drawn from the true rate."""
    rate = rng.uniform(0.0, 1.0, truths)
    docked = np.repeat((rng.random(truths) < rate).astype(float), copies)
    noisy = rate[:, None] + rng.normal(0.0, 0.01, (truths, copies))
    predicted = np.clip(0.5 + scale * (noisy.ravel() - 0.5), 0.0, 1.0)
    return predicted, docked, np.repeat(np.arange(truths), copies)


def test_clustered_z_accepts_calibrated_copies_that_the_classic_z_rejects():
    """120 truths, 9 near copies of each attempt, calibrated: the classic z sees 1,080
    independent attempts and rejects far more often than 5 % (13 of 40 seeds); the
    clustered one about 5 % (2 of 40)."""
    classic = clustered = 0
    for seed in range(40):
        predicted, docked, truth = _replicated(np.random.default_rng(seed), 120, 9)
        classic += abs(calibration.spiegelhalter_z(predicted, docked)) > 1.96
        clustered += abs(calibration.clustered_spiegelhalter_z(predicted, docked, truth)) > 1.96
    assert classic >= 8 and clustered <= 5


def test_clustered_z_still_rejects_predictions_shrunk_to_the_middle():
    rejected = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        predicted, docked, truth = _replicated(rng, 300, 9, scale=0.5)
        rejected += calibration.clustered_spiegelhalter_z(predicted, docked, truth) < -1.96
    assert rejected == 20


def test_clustered_z_ignores_exact_copies_and_matches_the_classic_z_on_singletons():
    rng = np.random.default_rng(3)
    p = rng.uniform(0.0, 1.0, 3000)
    docked = (rng.random(3000) < p).astype(float)
    single = calibration.clustered_spiegelhalter_z(p, docked, np.arange(3000))
    copied = calibration.clustered_spiegelhalter_z(
        np.repeat(p, 4), np.repeat(docked, 4), np.repeat(np.arange(3000), 4)
    )
    assert copied == pytest.approx(single)
    assert single == pytest.approx(calibration.spiegelhalter_z(p, docked), abs=0.15)
    assert calibration.spiegelhalter_z(np.repeat(p, 4), np.repeat(docked, 4)) == pytest.approx(
        2 * calibration.spiegelhalter_z(p, docked)
    )


def test_clustered_z_refuses_a_label_count_mismatch_and_gives_no_test_without_variance():
    with pytest.raises(ValueError):
        calibration.clustered_spiegelhalter_z([0.5, 0.5], [0, 1], [0])
    assert calibration.clustered_spiegelhalter_z([0.0, 1.0], [0, 1], [0, 1]) == 0.0


def test_a_calibrated_predictors_ece_floor_counts_clusters_not_attempts():
    """Copies that share a cluster (a truth's same attempt in 9 episodes) add nothing: the
    floor of 9 copies of 300 attempts is that of the 300, draw for draw; as 2,700 independent
    attempts it is lower. At 1,000 independent attempts the median is ~0.02."""
    rng = np.random.default_rng(5)
    p = rng.uniform(0.0, 1.0, 300)
    alone = calibration.calibrated_ece(p, np.arange(300), np.random.default_rng(1), draws=200)
    copies = calibration.calibrated_ece(
        np.repeat(p, 9), np.repeat(np.arange(300), 9), np.random.default_rng(1), draws=200
    )
    np.testing.assert_allclose(copies, alone)
    independent = calibration.calibrated_ece(
        np.repeat(p, 9), np.arange(2700), np.random.default_rng(1), draws=200
    )
    assert np.median(independent) < 0.7 * np.median(alone)
    thousand = calibration.calibrated_ece(
        rng.uniform(0.0, 1.0, 1000), np.arange(1000), np.random.default_rng(2), draws=200
    )
    assert 0.01 < np.median(thousand) < 0.035 and np.all(thousand >= 0)


def test_the_calibrated_floor_refuses_bad_input():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="one label per attempt"):
        calibration.calibrated_ece([0.2, 0.4], [0], rng)
    with pytest.raises(ValueError, match="draws"):
        calibration.calibrated_ece([0.2, 0.4], [0, 1], rng, draws=0)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        calibration.calibrated_ece([0.2, 1.4], [0, 1], rng)
