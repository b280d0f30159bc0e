"""The converter's image options: WIDTHxHEIGHT parsing and the scaling of frames."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from so101.dataset.convert import image_size, resized


def test_image_size_reads_width_by_height_and_refuses_nonsense():
    assert image_size("128x96") == (128, 96)
    assert image_size("64X48") == (64, 48)
    for bad in ("128", "x96", "128x96x3", "4x4", "0x10", "axb"):
        with pytest.raises(argparse.ArgumentTypeError):
            image_size(bad)


def test_frames_are_scaled_to_width_by_height_with_area_averaging():
    frame = np.zeros((48, 64, 3), dtype=np.uint8)
    frame[:, 32:] = 200  # right half bright
    (small,) = resized([frame], 32, 24)
    assert small.shape == (24, 32, 3) and small.dtype == np.uint8
    assert small[:, :16].max() == 0 and small[:, 16:].min() == 200
    same = [frame]
    assert resized(same, 64, 48) is same  # already that size: untouched
