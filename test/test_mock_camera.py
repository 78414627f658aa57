"""The mock depth camera and the perceived prior the docking benchmark runs on."""

import numpy as np
import pytest

from tactile_dock_ros.core import explore, problems
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.mock_camera import (
    MockCamera,
    depth_prior,
    draw_calibration_error,
)
from tactile_dock_ros.tools.bench.docking import PERCEPTION_CONFIG

CONFIG = PerceptionConfig.load(PERCEPTION_CONFIG)


def _distance_to_polyline(points, polyline):
    a, b = polyline[:-1], polyline[1:]
    d = b - a
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None] - a, d) / np.sum(d * d, axis=1), 0, 1)
    closest = a + t[..., None] * d
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


def test_calibration_error_is_drawn_from_the_configured_covariance():
    first = draw_calibration_error(CONFIG.extrinsic, np.random.default_rng(1))
    again = draw_calibration_error(CONFIG.extrinsic, np.random.default_rng(1))
    other = draw_calibration_error(CONFIG.extrinsic, np.random.default_rng(2))
    assert first.shape == (6,) and np.array_equal(first, again)
    assert not np.allclose(first, other)
    draws = np.array(
        [draw_calibration_error(CONFIG.extrinsic, np.random.default_rng(s)) for s in range(3000)]
    )
    sigma = np.sqrt(np.diag(CONFIG.extrinsic.covariance))
    assert np.allclose(draws.std(axis=0), sigma, rtol=0.1)
    assert np.allclose(draws.mean(axis=0), 0.0, atol=4 * sigma / np.sqrt(len(draws)))


@pytest.mark.parametrize("name", problems.names())
def test_depth_prior_lies_on_the_truth_in_the_plane_frame(name):
    problem = problems.get(name)
    truth = problem.sample_ground_truth(np.random.default_rng(0))
    seen = depth_prior(truth, CONFIG, np.random.default_rng(3), calibration_error=np.zeros(6))
    assert isinstance(seen.prior, GaussianShape) and not np.any(seen.calibration_error)
    # a calibrated camera: the perceived mean sits within a few mm of the truth's outline
    assert np.median(_distance_to_polyline(seen.prior.mean_vertices, truth)) < 0.005
    # the drawn error moves the camera, so the prior moves with it, deterministically per seed
    drawn = [depth_prior(truth, CONFIG, np.random.default_rng(s)) for s in (4, 4, 5)]
    assert np.array_equal(drawn[0].calibration_error, drawn[1].calibration_error)
    assert np.array_equal(drawn[0].prior.mean, drawn[1].prior.mean)
    assert not np.allclose(drawn[0].calibration_error, drawn[2].calibration_error)


def test_episode_runs_on_a_given_prior():
    problem = problems.get("notch")
    truth = problem.sample_ground_truth(np.random.default_rng(0))
    seen = depth_prior(truth, CONFIG, np.random.default_rng(1)).prior
    assert seen.n_vertices != problem.prior.n_vertices
    result = explore.run_episode(problem, truth, "ours", np.random.default_rng(2), 2, prior=seen)
    assert result.outcome != "error", result.message
    assert result.cycles_log[0].samples.shape[1] == seen.n_vertices


def test_bad_camera_and_empty_image_are_rejected():
    with pytest.raises(ValueError, match="image size"):
        MockCamera(0, 240)
    with pytest.raises(ValueError, match="focal"):
        MockCamera(focal_px=-1.0)
    far = np.array([[50.0, 50.0], [49.0, 50.0]])  # out of range of the camera
    with pytest.raises(PerceptionError):
        depth_prior(far, CONFIG, np.random.default_rng(0))
