"""Shape model, history container, prior columns and benchmark problems."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tactile_dock_ros.core import prior, problems
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.core.shape import GaussianShape


def _shape(n=4, m=3, closed=False, seed=0):
    rng = np.random.default_rng(seed)
    return GaussianShape(rng.normal(size=2 * n), rng.normal(size=(2 * n, m)), closed, 0.4)


def test_edges_follow_vertex_order_and_close():
    assert _shape(4).edges.tolist() == [[0, 1], [1, 2], [2, 3]]
    assert _shape(4, closed=True).edges.tolist() == [[0, 1], [1, 2], [2, 3], [3, 0]]


def test_edge_gaussians_match_the_full_covariance():
    shape = _shape(5, 4, closed=True)
    cov = shape.basis @ shape.basis.T
    means, covs = shape.edge_gaussians()
    for e, (u, v) in enumerate(shape.edges):
        idx = [2 * u, 2 * u + 1, 2 * v, 2 * v + 1]
        np.testing.assert_allclose(means[e], shape.mean[idx])
        np.testing.assert_allclose(covs[e], cov[np.ix_(idx, idx)])


def test_moment_fit_recovers_mean_and_covariance():
    shape = _shape(3, 2)
    rng = np.random.default_rng(1)
    fit = GaussianShape.from_samples(shape.vertices(shape.sample_z(rng, 40_000)), False, 0.4)
    np.testing.assert_allclose(fit.mean, shape.mean, atol=0.05)
    np.testing.assert_allclose(fit.basis @ fit.basis.T, shape.basis @ shape.basis.T, atol=0.1)


@pytest.mark.parametrize(
    ("mean", "basis", "closed", "friction"),
    [
        (np.zeros(3), np.zeros((3, 1)), False, 0.5),  # odd length
        (np.zeros(2), np.zeros((2, 1)), False, 0.5),  # one vertex
        (np.zeros(4), np.zeros((4, 1)), True, 0.5),  # closed with two vertices
        (np.array([0, 0, 1, np.nan]), np.zeros((4, 1)), False, 0.5),
        (np.zeros(4), np.full((4, 1), np.inf), False, 0.5),
        (np.zeros(4), np.zeros((4, 1)), False, -0.1),
    ],
)
def test_invalid_shapes_are_rejected(mean, basis, closed, friction):
    with pytest.raises(ValueError):
        GaussianShape(mean, basis, closed, friction)


def test_closure_edges_are_checked_sorted_and_kept_by_a_moment_fit():
    mean, basis = np.arange(8.0), np.eye(8)[:, :2]
    shape = GaussianShape(mean, basis, closure_edges=[2, 0, 2])
    assert shape.closure_edges == (0, 2)
    assert shape.with_mean_basis(mean, basis).closure_edges == (0, 2)
    with pytest.raises(ValueError, match="closure_edges"):
        GaussianShape(mean, basis, closure_edges=(3,))  # 4 vertices, open: edges 0-2


def test_history_validates_and_extends():
    h = History().extend([0, 0], [1, 0], Status.FREE).extend([1, 0], [1, -0.01], Status.STICK)
    assert len(h) == 2 and h.is_contact.tolist() == [False, True]
    assert len(h.subset(h.is_contact)) == 1
    with pytest.raises(ValueError, match="zero length"):
        History([[0, 0]], [[0, 0]], [Status.COLLIDE])
    with pytest.raises(ValueError, match="unknown contact status"):
        History([[0, 0]], [[1, 0]], [7])
    with pytest.raises(ValueError, match="finite"):
        History([[0, np.nan]], [[1, 0]], [0])
    with pytest.raises(ValueError, match="lengths"):
        History([[0, 0]], [[1, 0], [2, 0]], [0])


@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-0.05, 0.05))
def test_rotation_column_is_the_small_angle_rotation_about_the_sensor(sx, sy, angle):
    verts = np.array([[0.3, 0.2], [-0.1, 0.5], [0.7, -0.4]])
    sensor = np.array([sx, sy])
    col = prior.rotation_column(verts, sensor, 1.0)[:, 0].reshape(-1, 2)
    c, s = np.cos(angle), np.sin(angle)
    rotated = (verts - sensor) @ np.array([[c, s], [-s, c]]) + sensor
    np.testing.assert_allclose(verts + angle * col, rotated, atol=angle**2 + 1e-12)


def test_ray_columns_move_each_vertex_along_its_ray_only():
    verts = np.array([[1.0, 0.0], [0.0, 2.0]])
    cols = prior.ray_columns(verts, np.zeros(2), np.array([0.1, 0.2]))
    np.testing.assert_allclose(cols, [[0.1, 0], [0, 0], [0, 0], [0, 0.2]])


def test_problems_api():
    assert {"sloper", "notch", "three_ledges"} <= set(problems.names())
    with pytest.raises(ValueError, match="three_ledges"):
        problems.get("no_such_problem")
    assert problems.get("three_ledges").prior.n_vertices == 82
    for name in problems.names():
        p = problems.get(name)
        assert np.isclose(np.linalg.norm(p.load), 1.0)
        truth = p.sample_ground_truth(np.random.default_rng(3))
        assert truth.shape == (p.prior.n_vertices, 2) and np.all(np.isfinite(truth))
        again = p.sample_ground_truth(np.random.default_rng(3))
        np.testing.assert_array_equal(truth, again)
        # The start point is above the terrain (free side of a floor-like profile).
        assert p.start[1] > p.prior.mean_vertices[:, 1].max()
