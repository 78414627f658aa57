"""Rendered terrains -> slice -> prior: accuracy, hidden stretches, coverage, bad input."""

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.core.geometry2d import cross
from tactile_dock_ros.perception import evaluation, scenes
from tactile_dock_ros.perception.config import Extrinsic, PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.geometry import (
    perturb_pose,
    point_segment_distances,
)
from tactile_dock_ros.perception.render import render_depth
from tactile_dock_ros.perception.terrain_prior import (
    calibration_columns,
    calibration_jacobian,
    perceive,
)

K, T_NOMINAL = scenes.default_camera()
SIZE = (640, 480)
HALF_SIZE = (320, 240)  # the 50-terrain statistics run at half resolution to stay fast
HALF_K, _ = scenes.default_camera(*HALF_SIZE)
SPACING = 0.01


def _config(sigma_t=0.002, sigma_r_deg=0.2):
    return PerceptionConfig(Extrinsic.from_sigmas(T_NOMINAL, sigma_t, np.deg2rad(sigma_r_deg)))


def _run(terrain, config, seed, calibration_error=None, half_resolution=False):
    rng = np.random.default_rng(seed)
    size, K_run = (SIZE, K) if not half_resolution else (HALF_SIZE, HALF_K)
    depth = render_depth(
        terrain,
        K_run,
        T_NOMINAL,
        size,
        rng,
        config.depth_noise,
        calibration_error=calibration_error,
    )
    return perceive(depth, K_run, config, rng)


def _vertex_std(prior):
    """(n,) largest standard deviation of each vertex's 2x2 marginal."""
    A = prior.basis.reshape(prior.n_vertices, 2, -1)
    return np.sqrt(np.linalg.eigvalsh(A @ A.transpose(0, 2, 1))[:, -1])


def test_render_flat_wall_is_exact():
    wall = np.array([[0.0, -1.0], [0.0, 2.0]])
    depth = render_depth(wall, K, T_NOMINAL, SIZE, np.random.default_rng(0))
    v, u = np.nonzero(np.isfinite(depth))
    assert v.size == SIZE[0] * SIZE[1]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(u.size)], 1)
    pts = (depth[v, u, None] * rays) @ T_NOMINAL[:3, :3].T + T_NOMINAL[:3, 3]
    np.testing.assert_allclose(pts[:, 0], 0.0, atol=1e-5)


def _occluded_runs(terrain, camera_xy, mean_vertices, gap):
    """Truth (a, b): visible points bounding each in-view occluded run longer than ``gap``."""
    pts = evaluation.truth_points(terrain, 0.002)
    hidden = ~evaluation.visible_from(terrain, camera_xy, pts)
    hidden &= evaluation.in_view(pts, camera_xy, mean_vertices)
    edges = np.flatnonzero(np.diff(hidden.astype(int)))
    runs = []
    for start, stop in zip(edges[::2], edges[1::2], strict=False):
        a, b = pts[start], pts[stop + 1]
        if np.linalg.norm(b - a) > gap:
            runs.append((a, b))
    return runs


@pytest.mark.parametrize("name", sorted(scenes.TERRAINS))
def test_known_terrain_visible_parts_and_hidden_stretches(name):
    terrain = scenes.TERRAINS[name]()
    config = _config()
    result = _run(terrain, config, seed=7)
    sl, prior = result.slice, result.prior
    assert prior.n_vertices == len(sl.vertices) <= config.slice.max_vertices
    visible = ~sl.hidden
    mean = prior.mean_vertices
    sigma = _vertex_std(prior)
    # Slice -> truth: each visible vertex within 2 sigma + spacing of the true terrain.
    dist = point_segment_distances(mean[visible], terrain)
    assert np.all(dist <= 2 * sigma[visible] + sl.spacing_m), dist.max()
    # Truth -> slice: every truth point the camera sees (in view) is near the slice.
    pts = evaluation.truth_points(terrain, 0.005)
    seen = evaluation.visible_from(terrain, sl.camera_xy, pts)
    seen &= evaluation.in_view(pts, sl.camera_xy, mean)
    back = point_segment_distances(pts[seen], mean)
    assert np.all(back <= 2 * sigma.max() + sl.spacing_m), back.max()
    # Hidden stretches: one per true occlusion, ends at the truth's visible ends.
    runs = _occluded_runs(terrain, sl.camera_xy, mean, config.slice.gap_m)
    assert len(runs) >= 1
    assert len(sl.stretches) == len(runs)
    for a, b in runs:
        ends = [np.linalg.norm(mean[i] - a) + np.linalg.norm(mean[j] - b) for i, j in sl.stretches]
        assert min(ends) < 3 * sl.spacing_m
    # The hidden mean bulges to the solid side of each chord, inside the true occlusion.
    for i, j in sl.stretches:
        chord = mean[j] - mean[i]
        normal = np.array([-chord[1], chord[0]])
        assert np.all((mean[i + 1 : j] - mean[i]) @ normal > 0)


def test_slice_is_oriented_with_the_solid_on_the_left():
    result = _run(scenes.ledges(), _config(), seed=3)
    sl = result.slice
    v = result.prior.mean_vertices
    both_visible = ~sl.hidden[:-1] & ~sl.hidden[1:]
    # Outward normal (right of travel) faces the camera on seen edges.
    side = cross(np.diff(v, axis=0), sl.camera_xy - v[:-1])
    assert np.mean(side[both_visible] < 0) > 0.95


def _coverage_over_random_terrains(config, error_of_seed):
    covered, total, worst = 0.0, 0, 1.0
    for seed in range(50):
        rng = np.random.default_rng(1000 + seed)
        terrain = scenes.random_terrain(rng)
        result = _run(terrain, config, seed, error_of_seed(rng), half_resolution=True)
        frac, count = evaluation.coverage(result.prior, terrain, result.slice.camera_xy, SPACING)
        covered, total, worst = covered + frac * count, total + count, min(worst, frac)
    return covered / total, worst


def _calibration_error(rng):
    """1-2 cm translation in a random direction, 2 degrees about a random axis."""
    t, r = rng.standard_normal(3), rng.standard_normal(3)
    return np.r_[
        t / np.linalg.norm(t) * rng.uniform(0.01, 0.02), r / np.linalg.norm(r) * np.deg2rad(2)
    ]


def test_two_sigma_band_covers_random_terrains():
    pooled, worst = _coverage_over_random_terrains(_config(), lambda rng: None)
    assert pooled >= 0.9 and worst >= 0.7, (pooled, worst)


def test_calibration_error_is_covered_by_the_calibration_columns():
    calibrated = _config(sigma_t=0.015, sigma_r_deg=2.0)
    pooled, _ = _coverage_over_random_terrains(calibrated, _calibration_error)
    assert pooled >= 0.9, pooled
    # Control: the same errors with the tight calibration sigmas are NOT covered.
    pooled_tight, _ = _coverage_over_random_terrains(_config(), _calibration_error)
    assert pooled_tight < 0.8, pooled_tight


def test_calibration_jacobian_matches_finite_differences():
    ext = Extrinsic.from_sigmas(T_NOMINAL, 0.01, 0.01)
    verts = scenes.ledges()[1:-1]
    J = calibration_jacobian(verts, ext.camera_centre)
    cam_pts = (np.c_[verts, np.zeros(len(verts))] - T_NOMINAL[:3, 3]) @ T_NOMINAL[:3, :3]
    for axis in range(6):
        delta = np.zeros(6)
        delta[axis] = 1e-6
        moved = cam_pts @ perturb_pose(T_NOMINAL, delta)[:3, :3].T
        moved += perturb_pose(T_NOMINAL, delta)[:3, 3]
        np.testing.assert_allclose((moved[:, :2] - verts).ravel() / 1e-6, J[:, axis], atol=1e-4)


def test_calibration_error_displacement_lies_in_the_calibration_span():
    """A 2 cm / 2 degree error moves the slice almost exactly along the calibration columns."""
    config = _config(sigma_t=0.015, sigma_r_deg=2.0)
    error = np.r_[0.012, -0.015, 0.005, np.deg2rad([0.5, -0.8, 1.8])]
    result = _run(scenes.pocket_behind_lip(), config, seed=4, calibration_error=error)
    verts = result.prior.mean_vertices
    cam = (np.c_[verts, np.zeros(len(verts))] - T_NOMINAL[:3, 3]) @ T_NOMINAL[:3, :3]
    true_pose = perturb_pose(T_NOMINAL, error)
    shift = (cam @ true_pose[:3, :3].T + true_pose[:3, 3])[:, :2] - verts
    cols = calibration_columns(verts, config.extrinsic)
    coef, *_ = np.linalg.lstsq(cols, shift.ravel(), rcond=None)
    residual = shift.ravel() - cols @ coef
    assert np.abs(residual).max() < 2e-3
    assert np.linalg.norm(coef) < 3.0  # within the calibration Gaussian, not far out


def test_config_yaml_round_trip(tmp_path):
    data = {
        "perception": {
            "extrinsic": {"T_plane_camera": T_NOMINAL.tolist(), "covariance": np.eye(6).tolist()},
            "slice": {"vertex_spacing_m": 0.02},
            "friction": 0.7,
        }
    }
    path = tmp_path / "perception.yaml"
    path.write_text(yaml.safe_dump(data))
    config = PerceptionConfig.load(path)
    assert config.slice.vertex_spacing_m == 0.02 and config.friction == 0.7
    np.testing.assert_allclose(config.extrinsic.T_plane_camera, T_NOMINAL)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"slice": {"bogus": 1}}, "unknown keys"),
        ({"extrinsic": {"T_plane_camera": np.eye(3).tolist()}}, "4x4"),
        ({"extrinsic": {"T_plane_camera": (2 * np.eye(4)).tolist()}}, "rotation"),
        (
            {
                "extrinsic": {
                    "T_plane_camera": np.eye(4).tolist(),
                    "covariance": (-np.eye(6)).tolist(),
                }
            },
            "semi-definite",
        ),
        ({"depth_noise": {"sigma0_m": -1}}, "sigma0_m"),
        ({"occlusion": {"columns": 0}}, "occlusion"),
    ],
)
def test_config_errors(change, message):
    data = {"extrinsic": {"T_plane_camera": np.eye(4).tolist()}, **change}
    with pytest.raises(PerceptionError, match=message):
        PerceptionConfig.from_dict(data)


def test_bad_images_raise_clear_errors():
    config = _config()
    terrain = scenes.ledges()
    rng = np.random.default_rng(0)
    with pytest.raises(PerceptionError, match="no valid pixel"):
        perceive(np.full((480, 640), np.nan), K, config, rng)
    with pytest.raises(PerceptionError, match="2-D"):
        perceive(np.ones(10), K, config, rng)
    depth = render_depth(terrain, K, T_NOMINAL, SIZE, rng)
    away = T_NOMINAL.copy()
    away[2, 3] += 1.0  # the plane is 1 m to the side of every point
    missing = PerceptionConfig(Extrinsic.from_sigmas(away, 0.01, 0.01))
    with pytest.raises(PerceptionError, match="misses the image"):
        perceive(depth, K, missing, rng)
    sparse = np.full_like(depth, np.nan)
    sparse[:3] = depth[:3]  # a few rows: about 24 points in the band
    with pytest.raises(PerceptionError, match="need 30"):
        perceive(sparse, K, config, rng)


@given(seed=st.integers(0, 2**31), invalid=st.floats(0, 1))
@settings(max_examples=25, deadline=None)
def test_garbage_depth_gives_a_prior_or_a_perception_error(seed, invalid):
    rng = np.random.default_rng(seed)
    depth = rng.uniform(-1.0, 3.0, (48, 64))
    depth[rng.random(depth.shape) < invalid] = rng.choice([np.nan, np.inf, 0.0])
    small_K = K.copy()
    small_K[:2] /= 10
    try:
        result = perceive(depth, small_K, _config(), rng)
    except PerceptionError:
        return
    assert np.all(np.isfinite(result.prior.basis))


def test_shipped_config_runs_the_pipeline():
    from conftest import REPO_ROOT

    config = PerceptionConfig.load(REPO_ROOT / "config" / "perception_example.yaml")
    np.testing.assert_allclose(config.extrinsic.T_plane_camera, T_NOMINAL, atol=1e-5)
    result = _run(scenes.ledges(), config, seed=2)
    assert len(result.slice.stretches) == 2


def test_render_options_and_errors():
    wall = np.array([[0.0, -1.0], [0.0, 2.0]])
    rng = np.random.default_rng(0)
    narrow = render_depth(wall, K, T_NOMINAL, SIZE, rng, half_width_m=0.05)
    # Only the image columns within 5 cm of the plane see the extruded wall.
    cols = np.flatnonzero(np.isfinite(narrow).any(axis=0))
    assert 0 < cols.size < SIZE[0] / 2
    dropped = render_depth(wall, K, T_NOMINAL, SIZE, rng, dropout=0.3)
    assert 0.25 < np.isnan(dropped).mean() < 0.35
    with pytest.raises(ValueError, match="terrain_vertices"):
        render_depth(np.array([[0.0, np.nan], [0.0, 1.0]]), K, T_NOMINAL, SIZE, rng)
    with pytest.raises(ValueError, match="image size"):
        render_depth(wall, K, T_NOMINAL, (0, 10), rng)
