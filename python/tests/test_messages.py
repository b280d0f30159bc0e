"""Decoding the stack's messages in so101 (shared by the bag reader and the rclpy tools):
images of both RGB byte orders with padded rows, compressed images (JPEG, PNG) with the format
strings image_transport writes, joint states in any order, unit round trips."""

from __future__ import annotations

import numpy as np
import pytest
from sensor_msgs.msg import CompressedImage, Image, JointState

from so101.messages import image_size, joint_positions, rgb_image
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


def compressed(pixels: np.ndarray, kind: str, format: str) -> CompressedImage:
    import io

    from PIL import Image as Pil

    out = io.BytesIO()
    Pil.fromarray(pixels).save(out, format=kind)
    return CompressedImage(format=format, data=out.getvalue())


def test_compressed_frames_decode_to_rgb_whatever_their_kind():
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, size=(6, 9, 3), dtype=np.uint8)
    for format in ("bgr8; png compressed bgr8", "rgb8; png compressed rgb8", "png"):
        msg = compressed(rgb, "PNG", format)
        assert image_size(msg) == (9, 6)
        assert np.array_equal(rgb_image(msg), rgb)  # lossless, in RGB order whatever the format says
    smooth = np.repeat(np.linspace(0, 250, 16, dtype=np.uint8)[None, :, None], 8, axis=0).repeat(3, axis=2)
    jpeg = rgb_image(compressed(smooth, "JPEG", "rgb8; jpeg compressed bgr8"))
    assert jpeg.shape == (8, 16, 3) and np.abs(jpeg.astype(int) - smooth).max() < 8
    jpeg[0, 0, 0] ^= 1  # writable, its own copy
    gray = rgb_image(compressed(rgb[..., 0].copy(), "PNG", "mono8; png compressed mono8"))
    assert np.array_equal(gray, np.repeat(rgb[..., :1], 3, axis=2))
    rgba = np.concatenate([rgb, np.full((6, 9, 1), 255, np.uint8)], axis=2)
    assert np.array_equal(rgb_image(compressed(rgba, "PNG", "rgba8; png compressed bgra8")), rgb)


def test_compressed_frames_that_are_no_camera_frame_are_errors():
    rgb = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match="expected jpeg or png"):
        rgb_image(compressed(rgb, "PNG", "rgb8; tiff compressed rgb8"))
    with pytest.raises(ValueError, match="depth"):
        rgb_image(compressed(rgb, "PNG", "16UC1; compressedDepth png"))
    with pytest.raises(ValueError, match="but the data is PNG"):
        rgb_image(compressed(rgb, "PNG", "jpeg"))
    with pytest.raises(ValueError, match="16-bit"):
        image_size(compressed(np.zeros((4, 4), np.uint16), "PNG", "mono16; png compressed mono16"))
    with pytest.raises(ValueError, match="no JPEG image"):
        image_size(CompressedImage(format="jpeg", data=bytes(32)))
    whole = compressed(np.random.default_rng(4).integers(0, 256, size=(32, 32, 3), dtype=np.uint8), "JPEG", "jpeg")
    truncated = CompressedImage(format="jpeg", data=bytes(whole.data)[: len(whole.data) - 200])
    assert image_size(truncated) == (32, 32)  # the header is whole
    with pytest.raises(ValueError, match="does not decode"):
        rgb_image(truncated)


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
