"""What so101_camera_node's fake camera serves (crates/so101_camera_node/src/fake.rs), for the tests
that compare what arrives with it."""

from __future__ import annotations

import io

import numpy as np


def picture(width: int, height: int, sequence: int) -> np.ndarray:
    """The fake camera's picture of frame `sequence` (so101_camera_node::fake::picture)."""
    x = np.arange(width) * 255 // max(width - 1, 1)
    y = np.arange(height) * 255 // max(height - 1, 1)
    image = np.zeros((height, width, 3), dtype=np.int64)
    image[:, :, 0] = x[None, :]
    image[:, :, 1] = y[:, None]
    image[:, :, 2] = (sequence * 8) % 256
    return image


def decoded(message) -> np.ndarray:
    from PIL import Image as PilImage

    return np.asarray(PilImage.open(io.BytesIO(bytes(message.data))).convert("RGB")).astype(np.int64)
