"""The out-of-library gate: the learned prior where the library explains the image, the generic
depth prior where it does not (``perception.prior_select``), and perception's ``learned``
source built from the launch file."""

from pathlib import Path

import numpy as np
import pytest
from node_helpers import launch_nodes, node_from_launch

from tactile_dock_ros.core import problems
from tactile_dock_ros.nodes import convert
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError
from tactile_dock_ros.perception.learned_prior import TerrainLibrary, slice_rays
from tactile_dock_ros.perception.mock_camera import MockCamera, draw_calibration_error
from tactile_dock_ros.perception.prior_select import (
    SINGLE_CLASS_MARGIN,
    fit_threshold,
    fit_thresholds,
    gate_thresholds,
    inlier_samples,
    select_prior,
)
from tactile_dock_ros.perception.terrain_prior import perceive
from tactile_dock_ros.tools.bench.splits import split_seed

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "config" / "terrain_classes.npz"
CONFIG = PerceptionConfig.load(REPO / "config" / "perception_mock.yaml")
CAMERA = MockCamera()


def _image(name: str, i: int) -> np.ndarray:
    """A test-split truth of problem ``name`` as the mock camera sees it."""
    base = split_seed("test", 0)
    p = problems.names().index(name)
    truth = problems.get(name).sample_ground_truth(np.random.default_rng([*base, p, i]))
    rng = np.random.default_rng([*base, p, i, 2])
    return CAMERA.render(truth, CONFIG, draw_calibration_error(CONFIG.extrinsic, rng), rng)


@pytest.mark.parametrize("name", problems.names())
def test_in_library_images_get_the_learned_prior_of_their_class(name):
    """Ten held-out images per class: at least 9 pass their class's gate (the train scans put
    ~1 % under it), each with its own class."""
    library = TerrainLibrary.load(SHIPPED)
    chosen = [
        select_prior(_image(name, i), CAMERA.K, CONFIG, library, np.random.default_rng(i))
        for i in range(10)
    ]
    learned = [c for c in chosen if c.model == "learned"]
    assert len(learned) >= 9
    for c in learned:
        assert c.class_name == name and c.prior is c.learned.prior
        assert c.prior.n_vertices == library.get(name).n_vertices
        assert c.min_inlier_fraction == library.get(name).min_inlier_fraction
        assert c.learned.inlier_fraction >= c.min_inlier_fraction
        assert name in c.reason


@pytest.mark.parametrize("name", problems.names())
def test_a_wall_the_library_does_not_know_gets_the_generic_prior(name):
    """The library without the truth's class: the nearest wall it does not know."""
    library = TerrainLibrary.load(SHIPPED).without(name)
    depth = _image(name, 1)
    chosen = select_prior(depth, CAMERA.K, CONFIG, library, np.random.default_rng(5))
    assert chosen.model == "generic" and chosen.class_name == ""
    assert chosen.learned.name != name  # the best class is named in the reason
    assert chosen.learned.inlier_fraction < chosen.min_inlier_fraction
    assert "out of library" in chosen.reason and chosen.learned.name in chosen.reason
    generic = perceive(depth, CAMERA.K, CONFIG, np.random.default_rng(5)).prior
    np.testing.assert_array_equal(chosen.prior.mean, generic.mean)
    np.testing.assert_array_equal(chosen.prior.basis, generic.basis)


def test_the_gate_is_the_best_class_s_unless_given():
    library = TerrainLibrary.load(SHIPPED).without("notch")
    depth = _image("notch", 0)
    rng = np.random.default_rng(0)
    first = select_prior(depth, CAMERA.K, CONFIG, library, rng)
    share, best = first.learned.inlier_fraction, first.learned.name
    assert first.min_inlier_fraction == library.get(best).min_inlier_fraction > share
    # the best class's own gate decides: moved just below the share, the image passes
    passing = library.with_gates({**library.gates, best: share})
    assert select_prior(depth, CAMERA.K, CONFIG, passing, rng).model == "learned"
    for gate, model in ((0.0, "learned"), (share, "learned"), (share + 1e-6, "generic")):
        chosen = select_prior(depth, CAMERA.K, CONFIG, library, rng, gate)
        assert (chosen.model, chosen.min_inlier_fraction) == (model, gate)
    assert gate_thresholds(library, None) == library.gates
    assert gate_thresholds(library, 0.5) == {name: 0.5 for name in library.names}
    half = library.with_gates({**library.gates, best: None})
    with pytest.raises(ValueError, match=f"no fitted min_inlier_fraction for \\['{best}'\\]"):
        gate_thresholds(half, None)
    assert gate_thresholds(half, 0.5)[best] == 0.5
    for bad in (-0.1, 1.1, float("nan")):
        with pytest.raises(ValueError, match="in \\[0, 1\\]"):
            gate_thresholds(library, bad)
    with pytest.raises(ValueError, match="min_inlier_fraction"):
        library.with_gates({name: 1.5 for name in library.names})


def test_an_image_without_a_slice_is_a_perception_error():
    library = TerrainLibrary.load(SHIPPED)
    empty = np.full((CAMERA.height, CAMERA.width), np.nan)
    with pytest.raises(PerceptionError):
        select_prior(empty, CAMERA.K, CONFIG, library, np.random.default_rng(0))


def test_fit_threshold_separates_or_keeps_the_library_s_images():
    rng = np.random.default_rng(1)
    inside = rng.uniform(0.97, 1.0, 500)
    outside = rng.uniform(0.3, 0.9, 500)
    low, high = np.quantile(inside, 0.01), np.quantile(outside, 0.99)
    assert fit_threshold(inside, outside) == pytest.approx(0.5 * (low + high))
    assert high < fit_threshold(inside, outside) < low
    # overlapping samples, or no second class: 1 % of the library's images fall back at most
    overlap = rng.uniform(0.5, 0.99, 500)
    assert fit_threshold(inside, overlap) == pytest.approx(low - SINGLE_CLASS_MARGIN)
    assert fit_threshold(inside, []) == pytest.approx(low - SINGLE_CLASS_MARGIN)
    assert fit_threshold([0.01, 0.01], []) == 0.0
    with pytest.raises(ValueError):
        fit_threshold([], outside)
    with pytest.raises(ValueError):
        fit_threshold([0.9, np.nan], outside)


def test_fit_thresholds_gives_each_class_its_own_gate():
    rng = np.random.default_rng(2)
    inside = {"a": rng.uniform(0.97, 1.0, 300), "b": rng.uniform(0.85, 1.0, 300), "c": []}
    outside = {"a": rng.uniform(0.3, 0.9, 200), "b": rng.uniform(0.3, 0.96, 200)}
    gates = fit_thresholds(inside, outside)
    assert gates["a"] == fit_threshold(inside["a"], outside["a"])  # separated: the midpoint
    assert gates["b"] == pytest.approx(np.quantile(inside["b"], 0.01) - SINGLE_CLASS_MARGIN)
    assert gates["b"] < gates["a"]
    pooled = fit_threshold(np.concatenate([inside["a"], inside["b"]]), np.concatenate(
        [outside["a"], outside["b"]]))  # fmt: skip
    assert gates["c"] == pooled  # no scan of its own
    assert fit_thresholds({"a": inside["a"]}, {}) == {"a": fit_threshold(inside["a"], [])}
    with pytest.raises(ValueError):
        fit_thresholds({"a": [], "b": []}, {})


def test_a_one_class_library_gets_a_gate_from_its_own_scans():
    """No second class: no out-of-library sample, the gate is the in-library rule alone."""
    library = TerrainLibrary((TerrainLibrary.load(SHIPPED).get("notch"),))
    rays = [slice_rays(_image("notch", i), CAMERA.K, CONFIG) for i in range(3)]
    inside, outside = inlier_samples(library, [(r, "notch") for r in rays], CONFIG)
    assert inside["notch"].size == 3 and outside["notch"].size == 0
    gates = fit_thresholds(inside, outside)
    assert gates["notch"] == fit_threshold(inside["notch"], [])


def _perception(tmp_path, library: TerrainLibrary | None = None, **arguments):
    """The perception node of the mock launch (``prior_source: depth`` unless given)."""
    if library is not None:
        library.save(tmp_path / "classes.npz")
        arguments["terrain_classes"] = str(tmp_path / "classes.npz")
    spec = launch_nodes("mock", **{"prior_source": "depth", **arguments})["perception"]
    return node_from_launch(spec, tmp_path)


def _capture(node, depth: np.ndarray) -> list:
    """Feed ``depth`` and its camera info to ``node``; the status messages it publishes."""
    statuses = []
    node.status_pub.publish = statuses.append
    header = convert.Header(frame_id="depth_camera")
    node.on_info(convert.camera_info(CAMERA.K, CAMERA.width, CAMERA.height, header))
    node.on_image(convert.depth_to_image(depth.astype(np.float32), header))
    return statuses


def test_perception_node_publishes_the_learned_prior_and_says_which(tmp_path):
    with _perception(tmp_path) as (node, _):
        statuses = _capture(node, _image("three_ledges", 1))
        hold = node.holds.get(1)
    assert (
        hold is not None and hold.prior.n_vertices == problems.get("three_ledges").prior.n_vertices
    )
    values = {kv.key: kv.value for kv in statuses[-1].values}
    assert values["model"] == "learned" and values["class"] == "three_ledges"
    assert float(values["inlier_fraction"]) >= float(values["min_inlier_fraction"])
    assert {f"log_evidence/{n}" for n in problems.names()} <= set(values)


def test_perception_node_falls_back_out_of_library(tmp_path):
    library = TerrainLibrary.load(SHIPPED).without("sloper")
    with _perception(tmp_path, library) as (node, _):
        statuses = _capture(node, _image("sloper", 0))
        hold = node.holds.get(1)
    values = {kv.key: kv.value for kv in statuses[-1].values}
    assert values["model"] == "generic" and values["class"] == ""
    assert values["best_class"] != "sloper"
    assert hold is not None and hold.prior.n_vertices not in (c.n_vertices for c in library.classes)


@pytest.mark.parametrize(
    "arguments, message",
    [({"terrain_classes": "/no/such/classes.npz"}, "terrain_classes"),
     ({"terrain_classes": str(REPO / "config" / "mock.yaml")}, "not a terrain class library")],
)  # fmt: skip
def test_perception_node_refuses_a_bad_library(tmp_path, arguments, message):
    with pytest.raises(ValueError, match=message), _perception(tmp_path, **arguments):
        pass


@pytest.mark.parametrize(
    "arguments, classes",
    [({"terrain_classes": ""}, False),  # no library: the generic prior (with a warning)
     ({"prior_source": "generic"}, False),
     ({"prior_source": "learned"}, True)],  # the earlier name of depth
)  # fmt: skip
def test_perception_node_uses_the_library_only_for_the_depth_source(tmp_path, arguments, classes):
    with _perception(tmp_path, **arguments) as (node, _):
        statuses = _capture(node, _image("three_ledges", 1))
        hold = node.holds.get(1)
    assert (node.library is not None) == classes
    values = {kv.key: kv.value for kv in statuses[-1].values}
    assert (values.get("model") == "learned") == classes
    class_vertices = problems.get("three_ledges").prior.n_vertices
    assert hold is not None and (hold.prior.n_vertices == class_vertices) == classes


def test_perception_node_needs_a_gate_for_an_ungated_library(tmp_path):
    shipped = TerrainLibrary.load(SHIPPED)
    ungated = shipped.with_gates({name: None for name in shipped.names})
    with pytest.raises(ValueError, match="min_inlier_fraction"), _perception(tmp_path, ungated):
        pass
