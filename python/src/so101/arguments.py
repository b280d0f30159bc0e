"""argparse value types shared by the CLIs, so each refusal reads the same wherever it is given."""

from __future__ import annotations

import argparse
from collections.abc import Callable

LARGEST_SIDE = 4096


def picture_size(smallest_side: int) -> Callable[[str], tuple[int, int]]:
    """A `type` for WIDTHxHEIGHT (the sim's --cameras notation), each side from `smallest_side`
    to 4096 pixels -> (width, height)."""

    def parse(text: str) -> tuple[int, int]:
        try:
            width, height = (int(part) for part in text.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: WIDTHxHEIGHT, e.g. 128x96") from None
        if not all(smallest_side <= side <= LARGEST_SIDE for side in (width, height)):
            raise argparse.ArgumentTypeError(f"{text!r}: each side from {smallest_side} to {LARGEST_SIDE} pixels")
        return width, height

    return parse


def at_least(low: int) -> Callable[[str], int]:
    """A `type` for a whole number of at least `low`."""

    def parse(text: str) -> int:
        value = int(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"{value}: at least {low}")
        return value

    return parse
