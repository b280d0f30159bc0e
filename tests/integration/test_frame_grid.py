"""frame_grid finds where a dataset's frames lie in a bag's time also where the arm rests (the same
state published many times), and refuses rows that no 1/fps grid of held states gives."""

from __future__ import annotations

import numpy as np
from frame_grid import frame_zero_instants

FPS = 30.0
STATE_RATE = 100.0


def resting_then_moving_then_resting() -> tuple[np.ndarray, np.ndarray]:
    """States at 100 Hz for 3 s: at rest for 1 s, a ramp for 1 s, at rest again (bit-identical
    states, as a settled sim publishes)."""
    times = np.arange(300) / STATE_RATE + 5.0
    ramp = np.clip((times - 6.0), 0.0, 1.0)
    states = np.stack([ramp * 40.0 + 10.0, -ramp * 20.0, np.full_like(ramp, 3.0)], axis=1)
    return times, states


def held_rows(times: np.ndarray, states: np.ndarray, t0: float, count: int) -> list[tuple[int, np.ndarray]]:
    """What a correct converter writes: frame j holds the latest state at or before t0 + j / 30,
    stored as float32."""
    rows = []
    for j in range(count):
        index = int(np.searchsorted(times, t0 + j / FPS + 1e-9, side="right")) - 1
        rows.append((j, states[index].astype(np.float32).astype(np.float64)))
    return rows


def test_frames_over_rest_and_motion_pin_frame_zero_to_one_state_period():
    times, states = resting_then_moving_then_resting()
    t0 = 5.4123
    rows = held_rows(times, states, t0, 70)
    sampled = rows[::7]
    allowed = frame_zero_instants(times, states, sampled, FPS, 1e-3)
    assert allowed and allowed[0][0] <= t0 < allowed[-1][1]
    assert allowed[-1][1] - allowed[0][0] <= 1 / STATE_RATE + 1e-5, allowed


def test_matching_each_frame_alone_is_ambiguous_at_rest():
    """Why the grid is found from all frames together: at rest, the closest bag state of two frames
    seven apart is one and the same message (what the old check took for 0 s between frames)."""
    times, states = resting_then_moving_then_resting()
    rows = held_rows(times, states, 6.5, 60)
    closest = [int(np.abs(states - row).max(axis=1).argmin()) for _, row in rows[-15::7]]
    assert len(set(closest)) == 1


def test_a_frame_held_too_long_has_no_grid():
    """A converter that repeats a frame (the grid slips by one frame) is caught."""
    times, states = resting_then_moving_then_resting()
    rows = held_rows(times, states, 5.9, 40)
    slipped = rows[:15] + [(j, row) for j, (_, row) in enumerate(rows[14:39], start=15)]
    assert frame_zero_instants(times, states, slipped, FPS, 1e-3) == []
    assert frame_zero_instants(times, states, rows, FPS, 1e-3) != []


def test_rows_that_are_no_bag_state_have_no_grid():
    times, states = resting_then_moving_then_resting()
    rows = held_rows(times, states, 5.9, 40)
    rows[20] = (20, rows[20][1] + 0.01)
    assert frame_zero_instants(times, states, rows, FPS, 1e-3) == []
