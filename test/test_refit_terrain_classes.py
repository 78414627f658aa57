"""Refitting the terrain classes from depth scans alone (``perception.class_refit``,
``tools.refit_terrain_classes``) on scans the mock camera renders."""

from pathlib import Path

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.perception import scenes
from tactile_dock_ros.perception.class_refit import _widened, refit_library
from tactile_dock_ros.perception.config import PerceptionConfig
from tactile_dock_ros.perception.learned_prior import TerrainClass, TerrainLibrary, slice_rays
from tactile_dock_ros.perception.mock_camera import MockCamera, draw_calibration_error
from tactile_dock_ros.tools import depth_scans, refit_terrain_classes
from tactile_dock_ros.tools.fit_terrain_classes import fit_library

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config" / "perception_mock.yaml"
SHIPPED = REPO / "config" / "terrain_classes.npz"


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    """21 rendered train scans: 3 random walls (no class), 6 of each problem."""
    folder = tmp_path_factory.mktemp("scans")
    config = PerceptionConfig.load(CONFIG)
    depth_scans.render_training(folder, 21, 0, config, refit_terrain_classes.RANDOM_PER_SEVEN)
    return folder


def _rays(folder):
    config = PerceptionConfig.load(CONFIG)
    K, size = depth_scans.intrinsics(folder, None)
    files = depth_scans.scan_files(folder)
    return [slice_rays(d, K, config) for _, d in depth_scans.depth_images(files, K, size, config)]


def test_em_pulls_a_displaced_template_back_to_the_walls_the_scans_see():
    """Six scans per class of known truths, two of walls no class describes. Template: each
    class's covariance around the truths' own mean moved 2 cm out of the wall. Refitted from the
    scans alone, every class's mean ends nearer the truths' mean than the template started
    (each scan's 1 cm calibration prior takes part of the offset); the evidence rises; the two
    walls are left out."""
    config = PerceptionConfig.load(CONFIG)
    camera = MockCamera()
    shipped = TerrainLibrary.load(SHIPPED)
    rng = np.random.default_rng(11)
    rays, truths = [], {}
    for c in shipped.classes:
        truths[c.name] = [problems.get(c.name).sample_ground_truth(rng) for _ in range(6)]
    walls = [scenes.random_terrain(rng) for _ in range(2)]
    for truth in [t for ts in truths.values() for t in ts] + walls:
        error = draw_calibration_error(config.extrinsic, rng)
        rays.append(slice_rays(camera.render(truth, config, error, rng), camera.K, config))
    shift = np.array([0.02, 0.0])
    template = TerrainLibrary(
        tuple(
            TerrainClass(c.name, np.mean(truths[c.name], axis=0) + shift, c.basis, c.closed)
            for c in shipped.classes
        )
    )
    refit = refit_library(
        template, rays, config, iterations=2, min_scans=3, min_inlier_fraction=0.5
    )
    evidence = [step.log_evidence for step in refit.steps]
    assert len(evidence) == 3 and evidence[1] > evidence[0]  # the widened template: step 0
    assert refit.kept == int(np.argmax(evidence)) > 0
    refitted = refit.library
    for step in refit.steps:
        assert list(step.assigned[-2:]) == [-1, -1]
        assert list(step.assigned[:-2]) == [k for k in range(3) for _ in range(6)]
    for start, after in zip(template.classes, refitted.classes, strict=True):
        target = np.mean(truths[start.name], axis=0)
        error = [np.sqrt(np.mean((c.mean - target) ** 2)) for c in (start, after)]
        assert error[1] < error[0], (start.name, error)
        assert after.n_vertices == start.n_vertices and after.closed == start.closed
    assert refitted.gates == template.gates == {name: None for name in template.names}


def test_refit_argument_checks_and_widening():
    config = PerceptionConfig.load(CONFIG)
    library = TerrainLibrary.load(SHIPPED)
    for kw in ({"iterations": 0}, {"min_scans": 1}, {"min_inlier_fraction": 1.5},
               {"init_floor_m": -0.001}):  # fmt: skip
        with pytest.raises(ValueError):
            refit_library(library, [], config, **kw)
    terrain = library.get("sloper")
    wide = _widened(terrain, 0.01)
    np.testing.assert_allclose(wide.covariance, terrain.covariance + 1e-4 * np.eye(24))
    assert _widened(terrain, 0.0) is terrain
    # classes with too few scans are kept as they were (widened), not refitted from nothing
    refit = refit_library(library, [], config, iterations=1, init_floor_m=0.0)
    assert refit.steps[0].assigned.size == 0
    for a, b in zip(library.classes, refit.library.classes, strict=True):
        np.testing.assert_array_equal(a.basis, b.basis)


def test_tool_writes_a_gated_library_the_node_loads(scans, tmp_path, capsys):
    template = tmp_path / "template.npz"
    fit_library(per_class=8, seed=1).save(template)
    out = tmp_path / "refit.npz"
    argv = [str(scans), "--classes", str(template), "--config", str(CONFIG), "--out", str(out)]
    assert refit_terrain_classes.main([*argv, "--iterations", "1", "--min-scans", "3"]) == 0
    library = TerrainLibrary.load(out)
    assert library.names == ["sloper", "notch", "three_ledges"]
    assert all(0.0 < gate < 1.0 for gate in library.gates.values())
    printed = capsys.readouterr().out
    assert "21 of 21 scans give a slice" in printed and "3 left out" in printed
    assert printed.count("(kept)") == 1
    assert "min_inlier_fraction" in printed


@pytest.mark.parametrize(
    "change",
    [["--iterations", "0"], ["--init-floor-mm", "-1"], ["--min-inlier-fraction", "1.5"],
     ["--min-scans", "1"], ["--render-training", "-1"], ["--out", "/no/such/dir/x.npz"]],
)  # fmt: skip
def test_tool_rejects_bad_arguments(change, tmp_path, capsys):
    argv = [str(tmp_path), "--classes", str(SHIPPED), "--config", str(CONFIG)]
    with pytest.raises(SystemExit) as exit_info:
        refit_terrain_classes.main([*argv, "--out", str(tmp_path / "x.npz"), *change])
    assert exit_info.value.code == 2 and "error:" in capsys.readouterr().err


@pytest.mark.parametrize(
    "setup, message",
    [("no_scans", "no \\*.png or \\*.npy"), ("bad_classes", "--classes"),
     ("no_camera_info", "camera_info.yaml")],
)  # fmt: skip
def test_tool_reports_unusable_input(setup, message, scans, tmp_path, capsys):
    folder, classes = tmp_path / "empty", SHIPPED
    folder.mkdir()
    if setup == "bad_classes":
        classes = tmp_path / "bad.npz"
        classes.write_bytes(b"garbage")
    if setup == "no_camera_info":
        (folder / "scan_0000.png").write_bytes((scans / "scan_0000.png").read_bytes())
    argv = [str(folder), "--classes", str(classes), "--config", str(CONFIG)]
    assert refit_terrain_classes.main([*argv, "--out", str(tmp_path / "x.npz")]) == 2
    assert message.replace("\\", "") in capsys.readouterr().err.replace("\\", "")
    assert not (tmp_path / "x.npz").exists()
