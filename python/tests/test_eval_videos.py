"""Evaluation videos a person can watch: small policy cameras enlarged by whole pixel repeats,
frames of different heights tiled side by side."""

from __future__ import annotations

import numpy as np

from so101.evaluate.episodes import WATCHABLE_HEIGHT, tile, watchable


def test_a_small_camera_is_enlarged_by_whole_repeats_to_a_watchable_height():
    frame = np.random.default_rng(0).integers(0, 255, size=(72, 96, 3), dtype=np.uint8)
    big = watchable(frame)
    assert big.shape == (360, 480, 3) and WATCHABLE_HEIGHT == 360
    # Every pixel became a 5x5 block of itself: nothing interpolated.
    assert np.array_equal(big[::5, ::5], frame) and np.array_equal(big[4::5, 4::5], frame)
    odd = watchable(frame[:50])  # 360 / 50 is not whole: the next whole factor, 8
    assert odd.shape == (400, 768, 3)


def test_a_frame_already_watchable_is_left_as_it_is():
    frame = np.zeros((480, 640, 3), np.uint8)
    assert watchable(frame) is frame


def test_tiles_put_the_enlarged_cameras_side_by_side_padded_to_the_tallest():
    top = np.full((48, 64, 3), 200, np.uint8)
    front = np.full((240, 320, 3), 100, np.uint8)
    frame = tile({"top": top, "front": front})
    # top: x8 -> 384x512; front: x2 -> 480x640.
    assert frame.shape == (480, 512 + 640, 3)
    assert (frame[:384, :512] == 200).all() and (frame[384:, :512] == 0).all() and (frame[:, 512:] == 100).all()
