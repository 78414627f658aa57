"""ChArUco extrinsic calibration on synthetic board images."""

import cv2
import numpy as np
import pytest
import yaml

from tactile_dock_ros.perception import scenes
from tactile_dock_ros.perception.calibration import BoardSpec, calibrate_extrinsic, render_board
from tactile_dock_ros.perception.config import PerceptionConfig, PerceptionError, extrinsic_to_dict

K, T_PLANE_CAMERA = scenes.default_camera()
SPEC = BoardSpec()


def _board_pose(rvec, tvec):
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float))[0]
    T[:3, 3] = tvec
    return T


@pytest.mark.parametrize(
    ("rvec", "tvec"),
    [((0.2, -0.3, 0.05), (-0.14, -0.1, 0.6)), ((-0.3, 0.4, 0.0), (-0.1, -0.12, 0.8))],
)
def test_recovers_the_extrinsic_within_its_covariance(rvec, tvec):
    T_camera_board = _board_pose(rvec, tvec)
    T_plane_board = T_PLANE_CAMERA @ T_camera_board
    image = render_board(SPEC, K, T_camera_board, (640, 480), np.random.default_rng(0))
    result = calibrate_extrinsic(image, K, SPEC, T_plane_board)
    assert result.corners >= 20 and result.reprojection_rms_px < 1.0
    T = result.extrinsic.T_plane_camera
    d_t = T[:3, 3] - T_PLANE_CAMERA[:3, 3]
    d_r = cv2.Rodrigues(T[:3, :3] @ T_PLANE_CAMERA[:3, :3].T)[0].ravel()
    assert np.linalg.norm(d_t) < 0.005 and np.rad2deg(np.linalg.norm(d_r)) < 0.5
    err = np.r_[d_t, d_r]
    cov = result.extrinsic.covariance
    assert err @ np.linalg.solve(cov, err) < 22.5  # chi-square, 6 dof, p = 0.999
    assert np.all(np.sqrt(np.diag(cov))[:3] < 0.01)  # and the covariance is informative
    # The result is the config format the perception loads.
    config = PerceptionConfig.from_dict({"extrinsic": extrinsic_to_dict(result.extrinsic)})
    np.testing.assert_allclose(config.extrinsic.T_plane_camera, T)


def test_no_board_is_a_clear_error():
    blank = np.full((480, 640), 200, np.uint8)
    with pytest.raises(PerceptionError, match="ChArUco corners"):
        calibrate_extrinsic(blank, K, SPEC, np.eye(4))
    with pytest.raises(PerceptionError, match="dictionary"):
        BoardSpec(dictionary="DICT_NOPE").board()


def test_calibrate_cli_writes_the_config_section(tmp_path):
    from tactile_dock_ros.tools import calibrate

    T_camera_board = _board_pose((0.2, -0.3, 0.05), (-0.14, -0.1, 0.6))
    image = render_board(SPEC, K, T_camera_board, (640, 480), np.random.default_rng(1))
    cv2.imwrite(str(tmp_path / "board.png"), image)
    (tmp_path / "pose.yaml").write_text(
        yaml.safe_dump({"T_plane_board": (T_PLANE_CAMERA @ T_camera_board).tolist()})
    )
    out = tmp_path / "perception.yaml"
    out.write_text(yaml.safe_dump({"perception": {"friction": 0.6}}))
    argv = [str(tmp_path / "board.png"), "--K", *map(str, K.ravel()), "--board-pose"]
    argv += [str(tmp_path / "pose.yaml"), "--out", str(out)]
    assert calibrate.main(argv) == 0
    config = PerceptionConfig.load(out)
    assert config.friction == 0.6
    np.testing.assert_allclose(config.extrinsic.T_plane_camera, T_PLANE_CAMERA, atol=0.01)
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((480, 640), 200, np.uint8))
    assert calibrate.main([str(tmp_path / "blank.png"), *argv[1:]]) == 1  # no board: exit 1
    for bad_pose in ("{}", "T_plane_board: [[1, 0], [0, 1]]", "T_plane_board: [[1, 2], [3]]"):
        (tmp_path / "bad.yaml").write_text(bad_pose)
        bad = [*argv[:-3], str(tmp_path / "bad.yaml"), "--out", str(out)]
        with pytest.raises(SystemExit):  # argparse error naming the file, no traceback
            calibrate.main(bad)
    (tmp_path / "empty.yaml").write_text("")
    assert calibrate.main([*argv[:-1], str(tmp_path / "empty.yaml")]) == 0  # empty: new config
