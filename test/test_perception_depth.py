"""Depth decoding of sensor_msgs/Image-shaped data and CameraInfo checks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.perception.config import PerceptionError
from tactile_dock_ros.perception.depth import check_intrinsics, decode_depth, encode_depth


def _image(encoding, bigendian, pad, values):
    """Raw bytes of a 16UC1 / 32FC1 image with ``pad`` junk bytes at the end of each row."""
    dtype = np.dtype("u2" if encoding == "16UC1" else "f4").newbyteorder(">" if bigendian else "<")
    rows = values.astype(dtype).view(np.uint8).reshape(values.shape[0], -1)
    padded = np.hstack([rows, np.full((len(rows), pad), 0xAB, np.uint8)])
    return padded.tobytes(), rows.shape[1] + pad


@given(
    encoding=st.sampled_from(["16UC1", "32FC1"]),
    bigendian=st.booleans(),
    pad=st.integers(0, 7),
    height=st.integers(1, 6),
    width=st.integers(1, 6),
    seed=st.integers(0, 2**31),
)
@settings(max_examples=60, deadline=None)
def test_decode_honours_step_and_byte_order(encoding, bigendian, pad, height, width, seed):
    rng = np.random.default_rng(seed)
    mm = rng.integers(1, 5000, (height, width))
    values = mm if encoding == "16UC1" else mm * 1e-3
    data, step = _image(encoding, bigendian, pad, values)
    depth = decode_depth(data, height, width, encoding, bigendian, step)
    np.testing.assert_allclose(depth, mm * 1e-3, rtol=1e-6)


@pytest.mark.parametrize("encoding", ["16UC1", "32FC1"])
@pytest.mark.parametrize("bigendian", [False, True])
def test_encode_decode_round_trip_and_invalid_pixels(encoding, bigendian):
    depth = np.array([[0.5, np.nan, 1.25], [0.0, 3.0, np.inf]])
    data, step = encode_depth(depth, encoding, bigendian)
    out = decode_depth(data, 2, 3, encoding, bigendian, step, min_range_m=0.4, max_range_m=2.0)
    np.testing.assert_allclose(out, [[0.5, np.nan, 1.25], [np.nan, np.nan, np.nan]])


def test_decode_accepts_a_uint8_array():
    data, step = encode_depth(np.full((3, 4), 1.5), "32FC1")
    out = decode_depth(np.frombuffer(data, np.uint8), 3, 4, "32FC1", False, step)
    assert np.all(out == 1.5)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"encoding": "rgb8"}, "not supported"),
        ({"encoding": "mono16"}, "not supported"),
        ({"step": 7}, "shorter than a row"),
        ({"height": 5}, "bytes"),
        ({"width": 0}, "positive"),
    ],
)
def test_decode_rejects_bad_fields(kwargs, message):
    data, step = encode_depth(np.ones((4, 4)), "16UC1")
    fields = {"height": 4, "width": 4, "encoding": "16UC1", "is_bigendian": False, "step": step}
    fields.update(kwargs)
    with pytest.raises(PerceptionError, match=message):
        decode_depth(data, **fields)


def test_camera_info_checks():
    K = [500.0, 0, 320, 0, 500, 240, 0, 0, 1]
    assert check_intrinsics(K, 480, 640, 480, 640).shape == (3, 3)
    with pytest.raises(PerceptionError, match="CameraInfo is 320x240"):
        check_intrinsics(K, 480, 640, 240, 320)
    with pytest.raises(PerceptionError, match="pinhole"):
        check_intrinsics([0.0, 0, 320, 0, 500, 240, 0, 0, 1], 480, 640, 480, 640)
    with pytest.raises(PerceptionError, match="9 finite"):
        check_intrinsics([np.nan] * 9, 480, 640, 480, 640)
