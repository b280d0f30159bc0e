"""Where a dataset's frames lie in a bag's time, found from the bag alone: the instants t0 at which
frame 0 can lie so that every sampled frame's state is the bag's state in force at t0 + j / fps
(zero-order hold: the latest state at or before that instant). An arm at rest publishes the same
state for many messages, so one frame alone may match many instants; the frames together pin t0
down (to one state period where the arm moves)."""

from __future__ import annotations

import math

import numpy as np

Intervals = list[tuple[float, float]]


def _merged(intervals: Intervals) -> Intervals:
    out: Intervals = []
    for low, high in sorted(intervals):
        if out and low <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], high))
        else:
            out.append((low, high))
    return out


def _intersection(a: Intervals, b: Intervals) -> Intervals:
    out, i, j = [], 0, 0
    while i < len(a) and j < len(b):
        low, high = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if low < high:
            out.append((low, high))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


def frame_zero_instants(
    times: np.ndarray, states: np.ndarray, frames: list[tuple[int, np.ndarray]], fps: float, tolerance: float
) -> Intervals:
    """The instants (as disjoint [low, high) intervals) at which frame 0 may lie. `times`, `states`:
    the bag's states, by time; `frames`: (frame number from 0, the dataset's state row); a row
    matches a bag state within `tolerance` (max abs difference). Empty: no 1/fps grid of held
    bag states gives these rows."""
    allowed: Intervals = [(-math.inf, math.inf)]
    slack = 1e-6  # the frame instants' floating-point error
    for number, row in frames:
        offset = number / fps
        matching = np.flatnonzero(np.abs(states - row).max(axis=1) < tolerance)
        held = [
            (times[i] - offset - slack, (times[i + 1] if i + 1 < len(times) else math.inf) - offset + slack) for i in matching
        ]
        allowed = _intersection(allowed, _merged(held))
        if not allowed:
            break
    return allowed
