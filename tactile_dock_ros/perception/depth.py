"""sensor_msgs/Image-shaped depth data <-> metres, and CameraInfo intrinsics checks.

The node-suite conversion module passes the message fields unchanged; nothing here imports ROS.
Encodings: ``16UC1`` unsigned millimetres (0 = no return) and ``32FC1`` float metres (NaN, inf
or 0 = no return), the two of REP 118. Distortion is NOT handled: subscribe to the rectified
depth image (``image_rect``), whose CameraInfo ``D`` is zero; only ``K`` is used.
"""

from __future__ import annotations

import numpy as np

from .config import PerceptionError

_DTYPES = {"16UC1": np.dtype("u2"), "32FC1": np.dtype("f4")}


def decode_depth(
    data: bytes | bytearray | memoryview | np.ndarray,
    height: int,
    width: int,
    encoding: str,
    is_bigendian: bool,
    step: int,
    min_range_m: float = 0.0,
    max_range_m: float = np.inf,
) -> np.ndarray:
    """Image fields -> (height, width) float32 depth in metres, NaN where invalid.

    ``data`` is the raw byte buffer (or a uint8 array of it); rows are ``step`` bytes apart (any
    padding after ``width`` pixels is skipped), pixels in the byte order ``is_bigendian`` says.
    Invalid: 0, NaN, inf, or outside [min_range_m, max_range_m]. Raises PerceptionError on an
    unknown encoding, non-positive size, a step shorter than a row or a buffer too short.
    """
    if encoding not in _DTYPES:
        raise PerceptionError(f"depth encoding {encoding!r} not supported; use 16UC1 or 32FC1")
    height, width, step = int(height), int(width), int(step)
    if height <= 0 or width <= 0:
        raise PerceptionError(f"image size must be positive, got {width}x{height}")
    dtype = _DTYPES[encoding].newbyteorder(">" if is_bigendian else "<")
    row_bytes = width * dtype.itemsize
    if step < row_bytes:
        raise PerceptionError(f"step {step} is shorter than a row of {row_bytes} bytes")
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    buf = np.ascontiguousarray(buf).reshape(-1).view(np.uint8)
    if buf.size < step * (height - 1) + row_bytes:
        raise PerceptionError(
            f"data holds {buf.size} bytes, {width}x{height} {encoding} with step {step} needs "
            f"{step * (height - 1) + row_bytes}"
        )
    rows = np.lib.stride_tricks.as_strided(buf, shape=(height, row_bytes), strides=(step, 1))
    raw = np.ascontiguousarray(rows).view(dtype).astype(np.float32)
    depth = raw * np.float32(1e-3) if encoding == "16UC1" else raw
    valid = np.isfinite(depth) & (depth > 0) & (depth >= min_range_m) & (depth <= max_range_m)
    return np.where(valid, depth, np.float32(np.nan))


def encode_depth(
    depth_m: np.ndarray, encoding: str = "32FC1", is_bigendian: bool = False
) -> tuple[bytes, int]:
    """(height, width) metres (NaN = no return) -> (data bytes, step) for an Image message.

    16UC1 rounds to millimetres, clips to 65535 mm and writes 0 for no return; 32FC1 keeps NaN.
    """
    if encoding not in _DTYPES:
        raise PerceptionError(f"depth encoding {encoding!r} not supported; use 16UC1 or 32FC1")
    depth = np.asarray(depth_m, float)
    if depth.ndim != 2:
        raise PerceptionError(f"depth must be 2-D, got shape {depth.shape}")
    dtype = _DTYPES[encoding].newbyteorder(">" if is_bigendian else "<")
    if encoding == "16UC1":
        mm = np.where(np.isfinite(depth) & (depth > 0), np.round(depth * 1e3), 0.0)
        out = np.clip(mm, 0, 65535).astype(dtype)
    else:
        out = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(dtype)
    return out.tobytes(), depth.shape[1] * dtype.itemsize


def check_intrinsics(K: np.ndarray, height: int, width: int, info_height: int, info_width: int):
    """CameraInfo K (9 values or 3x3) -> validated (3, 3) float array.

    Raises PerceptionError when the CameraInfo size differs from the image size or K is not a
    pinhole matrix with positive focal lengths.
    """
    if (int(info_height), int(info_width)) != (int(height), int(width)):
        raise PerceptionError(
            f"CameraInfo is {info_width}x{info_height} but the image is {width}x{height}"
        )
    K = np.asarray(K, float).reshape(-1)
    if K.size != 9 or not np.all(np.isfinite(K)):
        raise PerceptionError("K must hold 9 finite values")
    K = K.reshape(3, 3)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise PerceptionError(f"K is not a pinhole camera matrix: {K.tolist()}")
    return K
