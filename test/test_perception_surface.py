"""Depth prior surface model: pixel-count noise, correlation along the surface, calibration."""

import dataclasses

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.geometry2d import cross
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.perception import evaluation, scenes
from tactile_dock_ros.perception.config import (
    DepthNoise,
    PerceptionConfig,
    PerceptionError,
    SurfaceParams,
)
from tactile_dock_ros.perception.geometry import point_segment_distances
from tactile_dock_ros.perception.render import render_depth
from tactile_dock_ros.perception.slicing import band_points, extract_slice, profile_from_points
from tactile_dock_ros.perception.surface import ray_sigma, surface_columns
from tactile_dock_ros.perception.terrain_prior import perceive
from tactile_dock_ros.tools.bench import prior as bench_prior

MOCK = PerceptionConfig.load(bench_prior.MOCK_CONFIG)
# The slice's prior; the tail tests add the tails past its ends.
CONFIG = dataclasses.replace(MOCK, occlusion=dataclasses.replace(MOCK.occlusion, tail_m=0.0))
K = bench_prior.mock_intrinsics()


def _with_model(model, **surface):
    return dataclasses.replace(
        CONFIG, surface=dataclasses.replace(CONFIG.surface, depth_model=model, **surface)
    )


def _slice(terrain, seed=0):
    depth = render_depth(
        terrain,
        K,
        CONFIG.extrinsic.T_plane_camera,
        bench_prior.IMAGE,
        np.random.default_rng(seed),
        CONFIG.depth_noise,
    )
    return extract_slice(depth, K, CONFIG.extrinsic, CONFIG.slice)


def test_vertex_noise_is_that_of_a_median_of_its_pixels():
    sl = _slice(problems.get("sloper").sample_ground_truth(np.random.default_rng(1)))
    visible = ~sl.hidden
    assert np.all(sl.pixels[visible] >= 2) and np.all(sl.pixels[sl.hidden] == 0)
    assert sl.bin_pixels.sum() >= sl.pixels[visible].sum() / 2
    exact = SurfaceParams(quantization_m=0.0)
    one_pixel = ray_sigma(sl, CONFIG.extrinsic, CONFIG.depth_noise, SurfaceParams("independent"))
    median = ray_sigma(sl, CONFIG.extrinsic, CONFIG.depth_noise, exact)
    np.testing.assert_allclose(
        median[visible], 1.2533 * one_pixel[visible] / np.sqrt(sl.pixels[visible]), rtol=1e-4
    )
    more = dataclasses.replace(sl, pixels=4 * sl.pixels)
    quartered = ray_sigma(more, CONFIG.extrinsic, CONFIG.depth_noise, exact)
    np.testing.assert_allclose(quartered[visible], median[visible] / 2)
    # The depth resolution is a floor that no pixel count averages away.
    floor = ray_sigma(
        dataclasses.replace(sl, pixels=1e9 * sl.pixels),
        CONFIG.extrinsic,
        CONFIG.depth_noise,
        SurfaceParams(),
    )
    assert np.all(floor[visible] > 0.9 * 0.001 / np.sqrt(12))


def test_bin_medians_are_taken_at_the_mean_bearing():
    """On a wall slanted to the rays the plain median range (paired with the bin's mean
    bearing) is off the wall by up to a millimetre and a half; the slope-corrected one is not."""
    wall = np.array([[0.3, -0.5], [-0.3, 0.3]])
    depth = render_depth(
        wall, K, CONFIG.extrinsic.T_plane_camera, bench_prior.IMAGE, np.random.default_rng(0)
    )
    pts = band_points(depth, K, CONFIG.extrinsic, CONFIG.slice.band_half_width_m)
    camera = CONFIG.extrinsic.camera_centre[:2]
    spacing = CONFIG.slice.vertex_spacing_m
    corrected, counts = profile_from_points(pts, camera, spacing, jump_m=CONFIG.slice.gap_m)
    plain, _ = profile_from_points(pts, camera, spacing, jump_m=0.0)  # every bin "a jump"
    assert counts.sum() == len(pts)
    assert point_segment_distances(corrected, wall).max() < 1e-4
    assert point_segment_distances(plain, wall).max() > 5e-4


def _render(truth: np.ndarray) -> np.ndarray:
    """The mock camera's depth image (m) of a truth, calibrated camera, seeded noise."""
    return render_depth(
        truth,
        K,
        CONFIG.extrinsic.T_plane_camera,
        bench_prior.IMAGE,
        np.random.default_rng(0),
        CONFIG.depth_noise,
    )


def test_neighbouring_edges_are_correlated_and_evidence_moves_neighbours():
    truth = problems.get("sloper").sample_ground_truth(np.random.default_rng(2))
    depth = _render(truth)
    priors = {
        model: perceive(depth, K, _with_model(model), np.random.default_rng(1)).prior
        for model in ("independent", "correlated")
    }
    std_old, corr_old = evaluation.edge_angle_stats(priors["independent"])
    std_new, corr_new = evaluation.edge_angle_stats(priors["correlated"])
    assert np.median(corr_old) < 0 < np.median(corr_new)
    assert np.median(std_new) < 0.5 * np.median(std_old)
    # Condition the surface columns on one face vertex lying 2 mm off along its normal: its
    # neighbour follows it in the correlated model (one face), not in the independent one.
    sl = perceive(depth, K, CONFIG, np.random.default_rng(1)).slice
    moved = {}
    for model in ("independent", "correlated"):
        verts, cols = surface_columns(
            sl, CONFIG.extrinsic, CONFIG.depth_noise, SurfaceParams(model)
        )
        A = cols.reshape(len(verts), 2, -1)
        edge = verts[21] - verts[20]
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        a = normal @ A[20]
        moved[model] = 0.002 * (normal @ A[21] @ a) / (a @ a)
    assert moved["correlated"] > 0.0008 and abs(moved["independent"]) < 1e-4, moved


def test_coverage_in_band_and_nll_beats_the_independent_model():
    """30 terrains (18 random walls, 4 truths per problem) with drawn calibration errors: the
    points and the seen edges' directions are covered (0.954 here; with the earlier
    ``bend_sigma_rad`` 0.05 the directions were overconfident: 0.909)."""
    rows = [
        bench_prior.score_terrain(truth, CONFIG, K, "16UC1", 11 * i)
        for i, (_, truth) in enumerate(bench_prior.terrains(18, 4, seed=3))
    ]
    covered = sum(r["correlated"]["covered"] for r in rows)
    assert 0.93 <= covered / sum(r["correlated"]["points"] for r in rows) <= 0.99
    angles = sum(r["correlated"]["angles_covered"] for r in rows)
    assert 0.93 <= angles / sum(r["correlated"]["angles"] for r in rows) <= 0.99
    old, new = (np.array([r[m]["nll_per_vertex"] for r in rows]) for m in bench_prior.MODELS)
    assert new.mean() < old.mean() - 1.0, (old.mean(), new.mean())
    assert np.mean(new < old) >= 0.8


def test_edge_angle_errors_are_the_chord_turn_over_the_direction_std():
    """One 1 m edge whose far end moves 1 cm along the normal per unit z: direction std
    0.01 rad; a truth chord turned by 0.02 rad is 2 std off, a NaN end is skipped."""
    prior = GaussianShape(
        np.array([0.0, 0.0, 1.0, 0.0, 2.0, 0.0]), np.array([[0, 0, 0, 0.01, 0, 0.0]]).T
    )
    turned = np.array([[0.0, 0.0], [np.cos(0.02), np.sin(0.02)], [np.nan, np.nan]])
    z = evaluation.edge_angle_errors(prior, turned)
    assert z.shape == (1,) and abs(z[0]) == pytest.approx(2.0, rel=1e-3)


def test_matched_truth_undoes_the_calibration_error():
    wall = np.array([[0.0, -1.0], [0.0, 2.0]])
    mean = np.stack([np.full(5, 0.002), np.linspace(0.0, 0.4, 5)], axis=1)
    error = np.r_[0.01, -0.01, 0.0, 0.0, 0.0, 0.02]
    matched = evaluation.matched_truth(
        mean, np.zeros(5, bool), wall, CONFIG.extrinsic.T_plane_camera, error
    )
    np.testing.assert_allclose(matched[:, 0], 0.0, atol=1e-12)
    assert np.all(np.abs(matched[:, 1] - mean[:, 1]) > 0.005)  # the rigid part is kept


@pytest.mark.parametrize(
    ("surface", "message"),
    [
        ({"depth_model": "gp"}, "depth_model"),
        ({"variance_kept": 0.1}, "variance_kept"),
        ({"bend_sigma_rad": -1.0}, "bend_sigma_rad"),
        ({"quantization_m": "fine"}, "quantization_m"),
        ({"corner_threshold": float("nan")}, "corner_threshold"),
        ({"bogus": 1}, "unknown keys"),
    ],
)
def test_bad_surface_config_is_rejected(surface, message):
    data = {"extrinsic": {"T_plane_camera": np.eye(4).tolist()}, "surface": surface}
    with pytest.raises(PerceptionError, match=message):
        PerceptionConfig.from_dict(data)


def test_default_is_correlated_and_scenes_still_perceive():
    assert (
        PerceptionConfig.from_dict(
            {"extrinsic": {"T_plane_camera": np.eye(4).tolist()}}
        ).surface.depth_model
        == "correlated"
    )
    sl = _slice(scenes.random_terrain(np.random.default_rng(4)) - [0.0, 0.3])
    assert len(sl.pixels) == len(sl.vertices)
    exact = DepthNoise(sigma0_m=0.0, quadratic_per_m=0.0)
    verts, cols = surface_columns(sl, CONFIG.extrinsic, exact, SurfaceParams(quantization_m=0.0))
    assert np.all(np.isfinite(verts)) and np.all(np.isfinite(cols)) and cols.shape[1] > 0


def _with_and_without_tails(problem, seed, **tails):
    """(slice prior, the same with ``tails``) from one rendered truth of ``problem``."""
    depth = _render(problems.get(problem).sample_ground_truth(np.random.default_rng(seed)))
    plain = perceive(depth, K, CONFIG, np.random.default_rng(1))
    occlusion = dataclasses.replace(CONFIG.occlusion, **tails)
    tailed = perceive(
        depth, K, dataclasses.replace(CONFIG, occlusion=occlusion), np.random.default_rng(1)
    ).prior
    return plain, tailed


def test_ray_tails_continue_the_line_of_sight_past_both_ends():
    plain, tailed = _with_and_without_tails("notch", 3, tail_m=0.5, tail_model="ray")
    assert tailed.n_vertices == plain.prior.n_vertices + 2
    assert tailed.n_basis == plain.prior.n_basis  # nothing behind the ray was measured
    mean, ends, camera = (
        tailed.mean_vertices,
        plain.prior.mean_vertices[[0, -1]],
        plain.slice.camera_xy,
    )
    np.testing.assert_allclose(mean[1:-1], plain.prior.mean_vertices, atol=1e-12)
    for far, end in ((mean[0], ends[0]), (mean[-1], ends[1])):
        assert np.linalg.norm(far - end) == pytest.approx(0.5)
        assert abs(cross(end - camera, far - end)) < 1e-9  # on the ray, behind the end
        assert np.dot(end - camera, far - end) > 0
    A = tailed.basis.reshape(tailed.n_vertices, 2, -1)
    np.testing.assert_allclose(A[[0, -1]], A[[1, -2]])  # they move with their end vertices
    assert tailed.closure_edges == (0, tailed.n_edges - 1)  # no docking site (planner)
    assert plain.prior.closure_edges == ()


def test_hidden_tails_close_the_slice_ends_on_the_solid_side():
    plain, tailed = _with_and_without_tails("sloper", 1, tail_m=0.1, tail_model="bridge")
    k = (tailed.n_vertices - plain.prior.n_vertices) // 2
    assert k == 5
    mean, camera = tailed.mean_vertices, plain.slice.camera_xy
    np.testing.assert_allclose(mean[k:-k], plain.prior.mean_vertices, atol=1e-12)
    # Walking on (solid on the left), each tail lies behind the line of sight through its end.
    for end, tail, sign in ((mean[-k - 1], mean[-k:], 1.0), (mean[k], mean[:k], -1.0)):
        ray = end - camera
        assert np.all(sign * cross(ray, tail - end) >= 0)
        assert np.linalg.norm(tail - end, axis=1).max() > 0.05
    # The tails move with their end vertices (calibration) and have their own spread.
    A = tailed.basis.reshape(tailed.n_vertices, 2, -1)
    m = plain.prior.n_basis
    np.testing.assert_allclose(A[:k, :, :m], np.broadcast_to(A[k, :, :m], (k, 2, m)))
    assert np.linalg.norm(A[-k:, :, m:]) > 0.01
    e = tailed.n_edges
    assert tailed.closure_edges == (*range(k), *range(e - k, e))
    with pytest.raises(PerceptionError, match="tail_model"):
        PerceptionConfig.from_dict(
            {"extrinsic": {"T_plane_camera": np.eye(4).tolist()}, "occlusion": {"tail_model": "x"}}
        )
    with pytest.raises(PerceptionError, match="tail_m"):
        PerceptionConfig.from_dict(
            {"extrinsic": {"T_plane_camera": np.eye(4).tolist()}, "occlusion": {"tail_m": -1}}
        )
