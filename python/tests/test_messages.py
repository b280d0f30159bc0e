"""Decoding the stack's messages in so101 (shared by the bag reader and the rclpy tools):
images of both RGB byte orders with padded rows, joint states in any order, unit round trips."""

from __future__ import annotations

import numpy as np
import pytest
from sensor_msgs.msg import Image, JointState

from so101.messages import joint_positions, rgb_image
from so101.units import JOINT_LIMITS, JOINT_NAMES, lerobot_from_radians, radians_from_lerobot


def image(encoding: str, pixels: np.ndarray, pad: int = 0) -> Image:
    h, w, _ = pixels.shape
    rows = np.concatenate([pixels.reshape(h, w * 3), np.full((h, pad), 7, np.uint8)], axis=1)
    return Image(height=h, width=w, encoding=encoding, step=w * 3 + pad, data=rows.tobytes())


def test_rgb_and_bgr_frames_with_padded_rows_decode_to_the_same_rgb_array():
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    for pad in (0, 3):
        assert np.array_equal(rgb_image(image("rgb8", rgb, pad)), rgb)
        assert np.array_equal(rgb_image(image("bgr8", rgb[..., ::-1].copy(), pad)), rgb)
    decoded = rgb_image(image("rgb8", rgb))
    decoded[0, 0, 0] ^= 1  # writable, its own copy (torch takes it as is)


def test_other_encodings_and_short_buffers_are_errors():
    rgb = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match="mono8"):
        rgb_image(Image(height=4, width=4, encoding="mono8", step=4, data=bytes(16)))
    short = image("rgb8", rgb)
    short.data = bytes(10)
    with pytest.raises(ValueError, match="too short"):
        rgb_image(short)


def test_joint_states_by_name_in_any_order_and_incomplete_ones_refused():
    names = list(reversed(JOINT_NAMES))
    msg = JointState(name=names, position=[float(i) for i in range(6)])
    assert list(joint_positions(msg)) == [5.0, 4.0, 3.0, 2.0, 1.0, 0.0]
    assert joint_positions(JointState(name=JOINT_NAMES[:5], position=[0.0] * 5)) is None


def test_lerobot_units_round_trip_over_the_joint_ranges():
    rng = np.random.default_rng(2)
    radians = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], size=(100, 6))
    values = lerobot_from_radians(radians)
    assert np.all((values[:, 5] >= 0) & (values[:, 5] <= 100))
    assert np.allclose(values[:, :5], np.degrees(radians[:, :5]))
    assert np.allclose(radians_from_lerobot(values), radians)
