"""The mock profile's depth camera, and the prior the robot gets from it (Sec. III-A1).

``depth_prior`` is the one path from a ground-truth terrain to the prior a robot would perceive:
the camera really sits at the configured extrinsic displaced by a calibration error (drawn from
the configured extrinsic covariance unless given), renders the terrain with the configured depth
noise and real occlusion, and ``terrain_prior.perceive`` turns the image into a prior while
believing the nominal extrinsic. The truth, the camera pose and the prior share one frame: the
docking plane's (x, y in the plane, z along its normal), the frame of ``core.problems``.
``mock_hardware`` renders with the same :class:`MockCamera`; the docking benchmark runs the
whole path per truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.shape import GaussianShape
from .config import Extrinsic, PerceptionConfig
from .render import render_depth
from .terrain_prior import perceive


@dataclass(frozen=True)
class MockCamera:
    """A rectified pinhole depth camera: image size in pixels, focal length in pixels."""

    width: int = 320
    height: int = 240
    focal_px: float = 262.5

    def __post_init__(self) -> None:
        if int(self.width) < 1 or int(self.height) < 1:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if not (np.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"focal_px must be finite and > 0, got {self.focal_px}")

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsics, principal point at the image centre."""
        f, cx, cy = float(self.focal_px), (self.width - 1) / 2, (self.height - 1) / 2
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    def render(
        self,
        terrain: np.ndarray,
        config: PerceptionConfig,
        calibration_error: np.ndarray,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """(height, width) depth image in metres (NaN = no return) of ``terrain`` (n, 2)."""
        return render_depth(
            terrain,
            self.K,
            config.extrinsic.T_plane_camera,
            (self.width, self.height),
            rng,
            config.depth_noise,
            calibration_error=np.asarray(calibration_error, float),
        )


def draw_calibration_error(extrinsic: Extrinsic, rng: np.random.Generator) -> np.ndarray:
    """(6,) (tx, ty, tz m, rx, ry, rz rad) ~ N(0, extrinsic.covariance) (may be singular)."""
    values, vectors = np.linalg.eigh(extrinsic.covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    return root @ rng.standard_normal(6)


@dataclass(frozen=True)
class DepthPrior:
    """Result of ``depth_prior``: the perceived prior and the calibration error it was seen with."""

    prior: GaussianShape
    calibration_error: np.ndarray  # (6,)


def depth_prior(
    truth: np.ndarray,
    config: PerceptionConfig,
    rng: np.random.Generator,
    camera: MockCamera = MockCamera(),
    calibration_error: np.ndarray | None = None,
) -> DepthPrior:
    """Prior perceived from a depth image of the ground truth ``truth`` (n, 2, plane frame).

    ``rng`` draws, in this order, the calibration error (when ``calibration_error`` is None),
    the depth noise and the perception's occlusion samples. Raises ``PerceptionError`` when the
    image cannot give a prior.
    """
    error = (
        draw_calibration_error(config.extrinsic, rng)
        if calibration_error is None
        else np.asarray(calibration_error, float).reshape(6)
    )
    depth = camera.render(truth, config, error, rng)
    return DepthPrior(perceive(depth, camera.K, config, rng).prior, error)
