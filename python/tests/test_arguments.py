"""The CLIs' shared argparse types: one parser for WIDTHxHEIGHT, bounded by each caller."""

from __future__ import annotations

import argparse

import pytest

from so101.arguments import at_least, picture_size


def test_picture_size_takes_its_smallest_side_from_the_caller():
    assert picture_size(8)("8x8") == (8, 8)
    with pytest.raises(argparse.ArgumentTypeError, match="each side from 16 to 4096 pixels"):
        picture_size(16)("8x8")
    with pytest.raises(argparse.ArgumentTypeError, match="from 8 to 4096"):
        picture_size(8)("4097x8")
    with pytest.raises(argparse.ArgumentTypeError, match="WIDTHxHEIGHT"):
        picture_size(8)("96 by 72")


def test_at_least_refuses_smaller_numbers():
    assert at_least(0)("0") == 0
    with pytest.raises(argparse.ArgumentTypeError, match="-1: at least 0"):
        at_least(0)("-1")
