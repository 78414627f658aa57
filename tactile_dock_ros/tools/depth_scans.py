"""Folders of depth scans for the fit tools: reading them as the perception node decodes images,
their intrinsics, and rendering training scans with the mock camera.

A scan folder holds depth images of the docking plane, all from one camera pose: ``*.png``
16UC1 (millimetres, 0 = no return, as ``image_rect`` of a depth camera saves) and/or ``*.npy``
2-D float metres (NaN or 0 = no return), and optionally ``camera_info.yaml`` (the ROS
camera_calibration format: ``image_width``, ``image_height``, ``camera_matrix.data``).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..core import problems
from ..perception import scenes
from ..perception.config import PerceptionConfig, PerceptionError
from ..perception.depth import check_intrinsics, decode_depth, encode_depth
from ..perception.mock_camera import MockCamera, draw_calibration_error
from .bench.splits import split_seed

CAMERA_INFO = "camera_info.yaml"
SUFFIXES = (".png", ".npy")
RANDOM_PER_SEVEN = 5  # random walls per 7 rendered scenes; the other 2 are problem truths


class InputError(Exception):
    """Input the tool cannot use (exit status 2)."""


def write_camera_info(path: Path, K: np.ndarray, width: int, height: int) -> None:
    info = {
        "image_width": int(width),
        "image_height": int(height),
        "camera_name": "mock_depth",
        "camera_matrix": {"rows": 3, "cols": 3, "data": np.asarray(K, float).ravel().tolist()},
        "distortion_model": "plumb_bob",
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
    }
    path.write_text(yaml.safe_dump(info, sort_keys=False))


def read_camera_info(path: Path) -> tuple[np.ndarray, int, int]:
    """(K, width, height) from a camera_calibration YAML."""
    try:
        info = yaml.safe_load(path.read_text())
        width, height = int(info["image_width"]), int(info["image_height"])
        K = check_intrinsics(info["camera_matrix"]["data"], height, width, height, width)
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as err:
        raise InputError(f"{path}: not a camera_info YAML with image size and K ({err})") from None
    return K, width, height


def read_depth(path: Path, config: PerceptionConfig) -> np.ndarray:
    """(height, width) metres, NaN invalid, through ``depth.decode_depth`` as the node decodes."""
    if path.suffix == ".png":
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise InputError(f"{path}: cannot read the image")
        if image.dtype != np.uint16 or image.ndim != 2:
            raise InputError(
                f"{path}: not a 16UC1 depth image (dtype {image.dtype}, shape {image.shape}); "
                "save depth as single-channel 16-bit PNG in millimetres"
            )
        encoding, raw = "16UC1", image.astype("<u2")
    else:
        try:
            array = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as err:
            raise InputError(f"{path}: cannot read the array ({err})") from None
        if array.ndim != 2 or not np.issubdtype(array.dtype, np.number):
            raise InputError(f"{path}: need a 2-D numeric array of metres, got {array.shape}")
        encoding, raw = "32FC1", array.astype("<f4")
    height, width = raw.shape
    noise = config.depth_noise
    return decode_depth(
        raw.tobytes(),
        height,
        width,
        encoding,
        False,
        raw.strides[0],
        noise.min_range_m,
        noise.max_range_m,
    )


def scan_files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder")
    return sorted(p for p in folder.iterdir() if p.suffix in SUFFIXES and p.is_file())


def render_training(
    folder: Path,
    count: int,
    seed: int,
    config: PerceptionConfig,
    random_per_seven: int = RANDOM_PER_SEVEN,
) -> list[Path]:
    """Render ``count`` training scenes into ``folder`` with the mock camera (320x240 px, focal
    262.5 px) at the config's extrinsic displaced by a calibration error drawn from its
    covariance, as 16UC1 PNGs with a ``camera_info.yaml``: of every 7, ``random_per_seven``
    random walls (``scenes.random_terrain``), the rest the benchmark problems' truths in turn,
    drawn from the TRAIN seed stream (``tools.bench.splits``). ``folder`` must hold no scans
    yet. Returns the files written."""
    try:
        base = split_seed("train", seed)
    except ValueError as err:
        raise InputError(f"--seed: {err}") from None
    if folder.exists() and scan_files(folder):
        raise InputError(f"{folder} already holds scans; render into a new folder")
    folder.mkdir(parents=True, exist_ok=True)
    camera = MockCamera()
    rng = np.random.default_rng(base)
    names = problems.names()
    written = []
    for i in range(count):
        if i % 7 < random_per_seven:
            truth = scenes.random_terrain(rng)
        else:
            slot = i // 7 * (7 - random_per_seven) + i % 7 - random_per_seven
            truth = problems.get(names[slot % len(names)])
            truth = truth.sample_ground_truth(rng)
        error = draw_calibration_error(config.extrinsic, rng)
        depth = camera.render(truth, config, error, rng)
        data, _ = encode_depth(depth, "16UC1")
        image = np.frombuffer(data, "<u2").reshape(depth.shape)
        path = folder / f"scan_{i:04d}.png"
        if not cv2.imwrite(str(path), image):
            raise InputError(f"{path}: cannot write")
        written.append(path)
    write_camera_info(folder / CAMERA_INFO, camera.K, camera.width, camera.height)
    return written


def intrinsics(folder: Path, K: list[float] | None) -> tuple[np.ndarray, tuple[int, int] | None]:
    """(K, (width, height) or None): ``K`` (CameraInfo K, row-major) when given, else the
    folder's ``camera_info.yaml``."""
    if K is not None:
        try:
            return check_intrinsics(K, 1, 1, 1, 1), None
        except PerceptionError as err:
            raise InputError(f"--K: {err}") from None
    if (folder / CAMERA_INFO).is_file():
        K, width, height = read_camera_info(folder / CAMERA_INFO)
        return K, (width, height)
    raise InputError(f"give --K or put a {CAMERA_INFO} into {folder}")


def depth_images(
    files: list[Path], K: np.ndarray, size: tuple[int, int] | None, config: PerceptionConfig
) -> Iterator[tuple[Path, np.ndarray]]:
    """(path, depth in metres) per scan; every image must have the intrinsics' size (or, without
    one, the first image's)."""
    for path in files:
        depth = read_depth(path, config)
        if size is None:
            size = depth.shape[::-1]
            check_intrinsics(K, size[1], size[0], size[1], size[0])
        if depth.shape[::-1] != tuple(size):
            raise InputError(
                f"{path}: image is {depth.shape[1]}x{depth.shape[0]}, the intrinsics' / other "
                f"scans' size is {size[0]}x{size[1]}"
            )
        yield path, depth
