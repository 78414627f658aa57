"""Camera-to-plane extrinsic and its covariance from one image of a ChArUco board at a known pose.

The board (OpenCV ``aruco`` ChArUco, board frame: origin at the board's top-left chessboard
corner, x along the squares' rows, y down the board, z into it) is fixed at a known pose
``T_plane_board`` in the docking-plane frame. Detecting its corners and solving PnP gives
``T_camera_board``; then ``T_plane_camera = T_plane_board inv(T_camera_board)``.

Covariance: the PnP Gauss-Newton covariance ``s^2 (J^T J)^-1`` over (rvec, tvec), with ``s``
the reprojection RMS (floored at ``pixel_sigma_floor`` because a synthetic or very clean image
would otherwise claim an implausibly exact pose), pushed through the numeric Jacobian of the map
to the config's 6-vector (plane-axis translation, rotation about the camera centre, see
``config``). The board's own placement error is not modelled: add it to the result if known.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from .config import Extrinsic, PerceptionError


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares (columns, rows), square and marker sides in metres."""

    squares_x: int = 7
    squares_y: int = 5
    square_m: float = 0.04
    marker_m: float = 0.03
    dictionary: str = "DICT_5X5_100"

    def board(self) -> cv2.aruco.CharucoBoard:
        try:
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        except AttributeError:
            raise PerceptionError(f"unknown ArUco dictionary {self.dictionary!r}") from None
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_m, self.marker_m, dictionary
        )


@dataclass(frozen=True)
class CalibrationResult:
    extrinsic: Extrinsic
    reprojection_rms_px: float
    corners: int


def _pose(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, float).reshape(3)
    return T


def render_board(
    spec: BoardSpec,
    K: np.ndarray,
    T_camera_board: np.ndarray,
    image_size: tuple[int, int],
    rng: np.random.Generator,
    pixels_per_square: int = 100,
    noise_std: float = 2.0,
) -> np.ndarray:
    """Synthetic 8-bit grey image (height, width) of the board seen from ``T_camera_board``."""
    ppm = pixels_per_square / spec.square_m
    flat = spec.board().generateImage(
        (spec.squares_x * pixels_per_square, spec.squares_y * pixels_per_square), marginSize=0
    )
    board_from_pixel = np.array([[1 / ppm, 0, 0.5 / ppm], [0, 1 / ppm, 0.5 / ppm], [0, 0, 1]])
    H = K @ T_camera_board[:3, [0, 1, 3]] @ board_from_pixel
    width, height = image_size
    img = cv2.warpPerspective(flat, H, (width, height), flags=cv2.INTER_AREA, borderValue=200)
    img = img.astype(float) + noise_std * rng.standard_normal(img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def calibrate_extrinsic(
    image: np.ndarray,
    K: np.ndarray,
    spec: BoardSpec,
    T_plane_board: np.ndarray,
    pixel_sigma_floor: float = 0.3,
    min_corners: int = 6,
) -> CalibrationResult:
    """Estimate ``T_plane_camera`` and its 6x6 covariance from one grey image of the board.

    Raises PerceptionError when fewer than ``min_corners`` ChArUco corners are found.
    """
    board = spec.board()
    gray = np.asarray(image)
    if gray.ndim == 3:
        gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(gray)
    if corners is None or ids is None or len(ids) < min_corners:
        found = 0 if ids is None else len(ids)
        raise PerceptionError(f"found {found} ChArUco corners, need {min_corners}")
    obj, img = board.matchImagePoints(corners, ids)
    obj, img = obj.reshape(-1, 3), img.reshape(-1, 2)
    K = np.asarray(K, float)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise PerceptionError("solvePnP failed on the detected ChArUco corners")
    projected, jac = cv2.projectPoints(obj, rvec, tvec, K, None)
    residual = projected.reshape(-1, 2) - img
    dof = max(residual.size - 6, 1)
    rms = float(np.sqrt(np.sum(residual**2) / dof))
    J = jac[:, :6]
    cov_pnp = max(rms, pixel_sigma_floor) ** 2 * np.linalg.inv(J.T @ J)

    T_plane_board = np.asarray(T_plane_board, float)

    def plane_camera(params: np.ndarray) -> np.ndarray:
        return T_plane_board @ np.linalg.inv(_pose(params[:3], params[3:]))

    params = np.r_[rvec.ravel(), tvec.ravel()]
    T = plane_camera(params)
    G = np.empty((6, 6))
    step = 1e-6
    for i in range(6):  # six finite differences of a 4x4 product: no hot path
        moved = plane_camera(params + step * np.eye(6)[i])
        rot = moved[:3, :3] @ T[:3, :3].T
        G[:3, i] = (moved[:3, 3] - T[:3, 3]) / step
        G[3:, i] = Rotation.from_matrix(rot).as_rotvec() / step
    cov = G @ cov_pnp @ G.T
    return CalibrationResult(Extrinsic(T, 0.5 * (cov + cov.T)), rms, len(obj))
