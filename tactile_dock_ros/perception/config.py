"""Perception configuration: extrinsic with covariance, depth noise, slicing, occlusion.

YAML / dict format (every key optional except ``extrinsic.T_plane_camera``)::

    extrinsic:
      # Camera optical frame (x right, y down, z forward) -> docking-plane frame (x, y in the
      # plane, z along its normal). 4x4 row-major homogeneous matrix, metres.
      T_plane_camera: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
      # Uncertainty of that transform, order (tx, ty, tz, rx, ry, rz): translation in metres
      # along the PLANE axes, rotation in radians about the plane axes through the CAMERA CENTRE
      # (true pose: R = Exp(r) R_nominal, t = t_nominal + t). Either a 6x6 covariance ...
      covariance: null
      # ... or independent standard deviations (used when covariance is null).
      sigma_translation_m: [0.01, 0.01, 0.01]
      sigma_rotation_rad: [0.026, 0.026, 0.026]
    depth_noise:            # std of one depth pixel: sigma(z) = sigma0_m + quadratic_per_m * z^2
      sigma0_m: 0.001
      quadratic_per_m: 0.002
      min_range_m: 0.1      # depths outside [min, max] are invalid pixels
      max_range_m: 5.0
    slice:
      band_half_width_m: 0.006   # keep points with |z_plane| <= this
      vertex_spacing_m: 0.01     # resampling step of the visible terrain
      max_vertices: 160          # the spacing grows if the slice would need more
      min_points: 30             # fewer in-band points is an error
      gap_m: 0.02                # a jump wider than this between bearing-neighbours is hidden
    occlusion:
      bridge_sigma_m_per_sqrt_m: 0.3    # Brownian-bridge diffusion: std sigma*sqrt(length)
      columns: 6                         # PCA columns kept per hidden stretch
      samples: 256                       # constrained-HMC samples per stretch
      trajectories: 6                    # HMC trajectories per sample chain
      max_hidden_vertices: 30            # per stretch
    surface:                # how the visible slice's vertices deviate from the true surface
      depth_model: correlated            # or independent: one-pixel std per vertex (old model)
      quantization_m: 0.001              # depth resolution of the image (16UC1: 1 mm)
      bend_sigma_rad: 0.1                # std of the true surface's turn at a vertex
      corner_threshold: 2.0              # measured turns beyond this many noise stds are corners
      variance_kept: 0.995               # eigen-columns kept per visible run (fraction of trace)
    friction: 0.5                         # Coulomb coefficient given to the prior
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml


class PerceptionError(ValueError):
    """Input the perception cannot turn into a prior (bad image, plane, config, too few points)."""


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise PerceptionError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise PerceptionError(f"{name} must be finite and {'>=' if allow_zero else '>'} 0")
    return value


@dataclass(frozen=True)
class Extrinsic:
    """Camera-to-plane transform and its 6x6 covariance (order tx ty tz rx ry rz, see module)."""

    T_plane_camera: np.ndarray
    covariance: np.ndarray

    def __post_init__(self) -> None:
        T = np.asarray(self.T_plane_camera, float)
        cov = np.asarray(self.covariance, float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise PerceptionError(f"T_plane_camera must be a finite 4x4 matrix, got {T.shape}")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise PerceptionError("T_plane_camera rotation block is not a rotation matrix")
        if not np.allclose(T[3], [0, 0, 0, 1]):
            raise PerceptionError("T_plane_camera last row must be [0, 0, 0, 1]")
        if cov.shape != (6, 6) or not np.all(np.isfinite(cov)):
            raise PerceptionError(f"extrinsic covariance must be a finite 6x6, got {cov.shape}")
        if not np.allclose(cov, cov.T) or np.linalg.eigvalsh(cov).min() < -1e-12:
            raise PerceptionError("extrinsic covariance must be symmetric positive semi-definite")
        object.__setattr__(self, "T_plane_camera", T)
        object.__setattr__(self, "covariance", cov)

    @property
    def rotation(self) -> np.ndarray:
        return self.T_plane_camera[:3, :3]

    @property
    def camera_centre(self) -> np.ndarray:
        """(3,) camera position in the plane frame, metres."""
        return self.T_plane_camera[:3, 3]

    @classmethod
    def from_sigmas(
        cls, T_plane_camera: np.ndarray, sigma_translation_m, sigma_rotation_rad
    ) -> Extrinsic:
        sig = np.concatenate(
            [np.broadcast_to(sigma_translation_m, 3), np.broadcast_to(sigma_rotation_rad, 3)]
        )
        return cls(T_plane_camera, np.diag(np.asarray(sig, float) ** 2))


@dataclass(frozen=True)
class DepthNoise:
    """Per-pixel depth std sigma(z) = sigma0_m + quadratic_per_m * z^2, valid range in metres."""

    sigma0_m: float = 0.001
    quadratic_per_m: float = 0.002
    min_range_m: float = 0.1
    max_range_m: float = 5.0

    def __post_init__(self) -> None:
        _positive("depth_noise.sigma0_m", self.sigma0_m, allow_zero=True)
        _positive("depth_noise.quadratic_per_m", self.quadratic_per_m, allow_zero=True)
        _positive("depth_noise.min_range_m", self.min_range_m, allow_zero=True)
        if not self.max_range_m > self.min_range_m:
            raise PerceptionError("depth_noise.max_range_m must exceed min_range_m")

    def sigma(self, depth_m: np.ndarray) -> np.ndarray:
        return self.sigma0_m + self.quadratic_per_m * np.asarray(depth_m, float) ** 2


@dataclass(frozen=True)
class SliceParams:
    band_half_width_m: float = 0.006
    vertex_spacing_m: float = 0.01
    max_vertices: int = 160
    min_points: int = 30
    gap_m: float = 0.02

    def __post_init__(self) -> None:
        for name in ("band_half_width_m", "vertex_spacing_m", "gap_m"):
            _positive(f"slice.{name}", getattr(self, name))
        if self.max_vertices < 4 or self.min_points < 2:
            raise PerceptionError("slice.max_vertices must be >= 4 and min_points >= 2")


TAIL_MODELS = ("ray", "bridge")


@dataclass(frozen=True)
class OcclusionParams:
    bridge_sigma_m_per_sqrt_m: float = 0.3
    columns: int = 6
    samples: int = 256
    trajectories: int = 6
    max_hidden_vertices: int = 30
    tail_m: float = 0.0
    tail_model: str = "ray"

    def __post_init__(self) -> None:
        _positive("occlusion.bridge_sigma_m_per_sqrt_m", self.bridge_sigma_m_per_sqrt_m)
        _positive("occlusion.tail_m", self.tail_m, allow_zero=True)
        if self.tail_model not in TAIL_MODELS:
            raise PerceptionError(
                f"occlusion.tail_model must be one of {TAIL_MODELS}, got {self.tail_model!r}"
            )
        if min(self.columns, self.trajectories, self.max_hidden_vertices) < 1 or self.samples < 2:
            raise PerceptionError("occlusion counts must be >= 1 (samples >= 2)")


DEPTH_MODELS = ("correlated", "independent")


@dataclass(frozen=True)
class SurfaceParams:
    """Surface model of the visible slice (``terrain_prior.surface_columns`` explains each)."""

    depth_model: str = "correlated"
    quantization_m: float = 0.001
    bend_sigma_rad: float = 0.1
    corner_threshold: float = 2.0
    variance_kept: float = 0.995

    def __post_init__(self) -> None:
        if self.depth_model not in DEPTH_MODELS:
            raise PerceptionError(
                f"surface.depth_model must be one of {DEPTH_MODELS}, got {self.depth_model!r}"
            )
        _positive("surface.quantization_m", self.quantization_m, allow_zero=True)
        _positive("surface.bend_sigma_rad", self.bend_sigma_rad)
        _positive("surface.corner_threshold", self.corner_threshold, allow_zero=True)
        if not 0.5 <= float(self.variance_kept) <= 1.0:
            raise PerceptionError("surface.variance_kept must lie in [0.5, 1]")


@dataclass(frozen=True)
class PerceptionConfig:
    extrinsic: Extrinsic
    depth_noise: DepthNoise = field(default_factory=DepthNoise)
    slice: SliceParams = field(default_factory=SliceParams)
    occlusion: OcclusionParams = field(default_factory=OcclusionParams)
    surface: SurfaceParams = field(default_factory=SurfaceParams)
    friction: float = 0.5

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PerceptionConfig:
        """Build from the documented dict format; unknown keys raise PerceptionError."""
        if not isinstance(data, dict) or "extrinsic" not in data:
            raise PerceptionError("perception config needs an 'extrinsic' section")
        ext = dict(data["extrinsic"])
        unknown = set(ext) - {
            "T_plane_camera",
            "covariance",
            "sigma_translation_m",
            "sigma_rotation_rad",
        }
        if unknown or "T_plane_camera" not in ext:
            raise PerceptionError(f"extrinsic: need T_plane_camera; unknown keys {sorted(unknown)}")
        if ext.get("covariance") is not None:
            extrinsic = Extrinsic(ext["T_plane_camera"], ext["covariance"])
        else:
            extrinsic = Extrinsic.from_sigmas(
                ext["T_plane_camera"],
                ext.get("sigma_translation_m", 0.01),
                ext.get("sigma_rotation_rad", np.deg2rad(1.5)),
            )
        sections = {}
        for key, kind in (
            ("depth_noise", DepthNoise),
            ("slice", SliceParams),
            ("occlusion", OcclusionParams),
            ("surface", SurfaceParams),
        ):
            values = dict(data.get(key) or {})
            unknown = set(values) - {f.name for f in fields(kind)}
            if unknown:
                raise PerceptionError(f"{key}: unknown keys {sorted(unknown)}")
            sections[key] = kind(**values)
        unknown = set(data) - {"extrinsic", "friction", *sections}
        if unknown:
            raise PerceptionError(f"unknown perception config keys {sorted(unknown)}")
        friction = _positive("friction", data.get("friction", 0.5), allow_zero=True)
        return cls(extrinsic, friction=friction, **sections)

    @classmethod
    def load(cls, path: str | Path) -> PerceptionConfig:
        """Read a YAML file holding the dict format (optionally under a top-level 'perception')."""
        data = yaml.safe_load(Path(path).read_text())
        if isinstance(data, dict) and "perception" in data:
            data = data["perception"]
        return cls.from_dict(data)


def extrinsic_to_dict(extrinsic: Extrinsic) -> dict[str, Any]:
    """The ``extrinsic`` section of the config format (plain lists, YAML-ready)."""
    return {
        "T_plane_camera": extrinsic.T_plane_camera.tolist(),
        "covariance": extrinsic.covariance.tolist(),
    }
