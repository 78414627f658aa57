"""tools.fit_surface_prior: mock-camera training scans -> a perception config with a fitted
surface section; bad input -> exit status 2 and a message, no traceback."""

import json
import shutil

import numpy as np
import pytest
import yaml

from tactile_dock_ros.perception import surface_fit
from tactile_dock_ros.perception.config import PerceptionConfig
from tactile_dock_ros.tools import depth_scans, fit_surface_prior
from tactile_dock_ros.tools.bench import prior as bench_prior

MOCK = bench_prior.MOCK_CONFIG


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """8 training scans rendered and fitted in one call; (folder, out yaml, summary, status)."""
    root = tmp_path_factory.mktemp("fit")
    scans, out = root / "scans", root / "fitted.yaml"
    args = [str(scans), "--config", str(MOCK), "--render-training", "8", "--seed", "3"]
    status = fit_surface_prior.main([*args, "--out", str(out)])
    return scans, out, json.loads(out.with_suffix(".json").read_text()), status


def test_fit_writes_a_config_the_perception_loads(fitted):
    scans, out, summary, status = fitted
    assert status == 0
    assert len(list(scans.glob("scan_*.png"))) == 8 and (scans / "camera_info.yaml").is_file()
    config, source = PerceptionConfig.load(out), PerceptionConfig.load(MOCK)
    lo, hi = surface_fit.BEND_BOUNDS
    assert lo <= config.surface.bend_sigma_rad <= hi
    assert surface_fit.THRESHOLD_BOUNDS[0] <= config.surface.corner_threshold
    assert config.surface.corner_threshold <= surface_fit.THRESHOLD_BOUNDS[1]
    assert config.surface.bend_sigma_rad == pytest.approx(summary["fitted"]["bend_sigma_rad"], 1e-3)
    # everything else copied
    np.testing.assert_array_equal(config.extrinsic.covariance, source.extrinsic.covariance)
    assert config.slice == source.slice and config.occlusion == source.occlusion
    assert config.surface.variance_kept == source.surface.variance_kept
    assert summary["scans_used"] == summary["scans_found"] == 8 and "warning" in summary
    assert (
        summary["rows"] > 50
        and summary["expected_log_score_per_row"]["after"]
        >= (summary["expected_log_score_per_row"]["before"])
    )


def test_npy_metres_and_png_millimetres_read_alike(fitted, tmp_path):
    scans = fitted[0]
    config = PerceptionConfig.load(MOCK)
    png = depth_scans.read_depth(scans / "scan_0000.png", config)
    np.save(tmp_path / "scan.npy", png)
    np.testing.assert_array_equal(depth_scans.read_depth(tmp_path / "scan.npy", config), png)


def test_render_alone_writes_scans_and_no_config(tmp_path):
    folder = tmp_path / "scans"
    args = [str(folder), "--config", str(MOCK), "--render-training", "2"]
    assert fit_surface_prior.main(args) == 0
    assert len(list(folder.glob("*.png"))) == 2
    assert fit_surface_prior.main(args) == 2  # the folder holds scans now


def test_help_exits_zero(capsys):
    with pytest.raises(SystemExit) as stop:
        fit_surface_prior.main(["--help"])
    assert stop.value.code == 0
    assert "--render-training" in capsys.readouterr().out


def _copy_scans(fitted, tmp_path, count=2):
    folder = tmp_path / "scans"
    folder.mkdir()
    for path in sorted(fitted[0].glob("scan_*.png"))[:count]:
        shutil.copy(path, folder)
    shutil.copy(fitted[0] / "camera_info.yaml", folder)
    return folder


def _bad_config(tmp_path, text):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return path


def _empty(folder, tmp):
    (tmp / "empty").mkdir()
    return tmp / "empty", MOCK, []


def _unreadable(folder, tmp):
    (folder / "broken.png").write_bytes(b"not a png")
    return folder, MOCK, []


def _colour(folder, tmp):
    import cv2

    cv2.imwrite(str(folder / "colour.png"), np.zeros((240, 320, 3), np.uint8))
    return folder, MOCK, []


def _wrong_size(folder, tmp):
    np.save(folder / "small.npy", np.ones((120, 160)))
    return folder, MOCK, []


def _no_intrinsics(folder, tmp):
    (folder / "camera_info.yaml").unlink()
    return folder, MOCK, []


def _independent(folder, tmp):
    document = yaml.safe_load(MOCK.read_text())
    document["surface"] = {"depth_model": "independent"}
    return folder, _bad_config(tmp, yaml.safe_dump(document)), []


# case -> setup(folder with two scans, tmp_path) -> (folder, config, extra arguments)
BAD = {
    "empty folder": _empty,
    "missing folder": lambda f, t: (t / "nowhere", MOCK, []),
    "unreadable image": _unreadable,
    "colour image": _colour,
    "wrong size": _wrong_size,
    "no intrinsics": _no_intrinsics,
    "bad K": lambda f, t: (f, MOCK, ["--K", "0", "0", "160", "0", "262.5", "120", "0", "0", "1"]),
    "missing config": lambda f, t: (f, t / "missing.yaml", []),
    "config error": lambda f, t: (f, _bad_config(t, "extrinsic: {T_plane_camera: [[1, 0]]}\n"), []),
    "not yaml": lambda f, t: (f, _bad_config(t, "extrinsic: [unclosed\n"), []),
    "independent model": _independent,
    "no out": lambda f, t: (f, MOCK, []),
    "seed out of range": lambda f, t: (
        t / "render",
        MOCK,
        ["--render-training", "1", "--seed", "-1"],
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_exits_2_with_a_message(case, fitted, tmp_path, capsys):
    folder, config, extra = BAD[case](_copy_scans(fitted, tmp_path), tmp_path)
    out = tmp_path / "out.yaml"
    args = [str(folder), "--config", str(config), *extra]
    if case != "no out":
        args += ["--out", str(out)]
    assert fit_surface_prior.main(args) == 2
    err = capsys.readouterr().err
    assert "fit_surface_prior: error:" in err and "Traceback" not in err
    assert not out.exists()
