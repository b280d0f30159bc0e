"""Putting streams recorded at their own rates onto the dataset's frame grid. Pure functions.

Alignment (also in docs/lerobot.md): every stream is a list of (time, value) in sim time. Frame k
of an episode is at t_k = t_0 + k / fps, where t_0 is half a frame after the first instant at which
every stream has delivered a message. Half a frame: a stream at the dataset's rate (a camera at
30 fps) then has its messages half a period away from every t_k. Starting at that instant itself
would put them on the t_k, where a stamp's jitter (or float64's 0.2 us at epoch times) decides
between two frames: rows would repeat one frame and skip the next. Each stream contributes its
latest value at or before t_k (zero-order hold:
what the policy would have seen, or the command in force, at that instant). The episode ends at
the last t_k not later than the end of the shortest stream plus one of its periods, so no frame
holds a value far beyond its stream's last message.
"""

from __future__ import annotations

import bisect

import numpy as np


def frame_times(streams: dict[str, list[float]], fps: float, hold_limit: dict[str, float] | None = None) -> np.ndarray:
    """The frame instants for streams with the given (sorted) message times. `hold_limit` gives,
    per stream, how long past its last message a value may be held (default: one frame)."""
    if not streams or any(len(times) == 0 for times in streams.values()):
        return np.zeros(0)
    start = max(times[0] for times in streams.values()) + 0.5 / fps
    limits = hold_limit or {}
    end = min(times[-1] + limits.get(name, 1.0 / fps) for name, times in streams.items())
    if end < start:
        return np.zeros(0)
    count = int(np.floor((end - start) * fps + 1e-9)) + 1
    return start + np.arange(count) / fps


def sample_and_hold(times: list[float], instants: np.ndarray) -> np.ndarray:
    """Index of the latest message at or before each instant (every instant must be at or after
    the first message)."""
    indices = np.array([bisect.bisect_right(times, t + 1e-9) - 1 for t in instants], dtype=np.int64)
    if len(indices) and indices.min() < 0:
        raise ValueError("an instant lies before the stream's first message")
    return indices


class WallToSim:
    """Maps recorder receive times (wall clock) to sim time through messages that carry both (the
    joint states: header stamp = sim time), so streams without a stamp of their own can be placed
    on the sim's clock whatever the sim's speed was."""

    def __init__(self, wall: list[float], sim: list[float]):
        if len(wall) < 2:
            raise ValueError("too few stamped messages to map receive times to sim time")
        order = np.argsort(wall)
        self.wall = np.asarray(wall, dtype=np.float64)[order]
        self.sim = np.asarray(sim, dtype=np.float64)[order]
        # A receive time is at least as late as the sim time it carried: the running maximum keeps
        # the map monotonic despite delivery jitter.
        self.sim = np.maximum.accumulate(self.sim)

    def __call__(self, wall_times) -> np.ndarray:
        return np.interp(np.asarray(wall_times, dtype=np.float64), self.wall, self.sim)


# A command's own stamp places it when it is the stamp of a recorded joint state (the state it
# answers: teleop_node's lockstep commands) lying near the command's arrival: up to 1 s before, up
# to 0.1 s after (the recorder takes each topic on its own, so a command may come in a moment before
# the state it answers). A stamp of the publisher's own clock (its publish time) is none of these.
STAMP_BEFORE_ARRIVAL_S = 1.0
STAMP_AFTER_ARRIVAL_S = 0.1
SAME_STAMP_S = 1e-6


def command_times(arrivals: np.ndarray, stamps: np.ndarray, state_stamps: np.ndarray) -> np.ndarray:
    """Sim time of each command, given in arrival order: its stamp where that is a recorded
    state's (above), else its arrival; never earlier than a command that arrived before it (the
    robot obeyed them in that order). Placed by arrival, a lockstep command that came in after the
    middle of its period landed a frame late, as the machine's load decided."""
    arrivals = np.asarray(arrivals, dtype=np.float64)
    stamps = np.asarray(stamps, dtype=np.float64)
    known = np.sort(np.asarray(state_stamps, dtype=np.float64))
    if len(known):
        after = np.clip(np.searchsorted(known, stamps), 0, len(known) - 1)
        before = np.clip(after - 1, 0, len(known) - 1)
        on_state = np.minimum(np.abs(known[after] - stamps), np.abs(known[before] - stamps)) <= SAME_STAMP_S
    else:
        on_state = np.zeros(len(stamps), dtype=bool)
    ahead = stamps - arrivals
    trusted = (stamps > 0) & on_state & (ahead >= -STAMP_BEFORE_ARRIVAL_S) & (ahead <= STAMP_AFTER_ARRIVAL_S)
    placed = np.where(trusted, stamps, arrivals)
    return np.maximum.accumulate(placed) if len(placed) else placed


def gaps(streams: dict[str, list[float]], max_gap: float) -> list[tuple[str, float, float]]:
    """(stream, last time before, first time after) of every silence longer than `max_gap` between
    two consecutive messages of a stream, by start time."""
    found = []
    for name, times in streams.items():
        steps = np.diff(np.asarray(times, dtype=np.float64))
        found.extend((name, float(times[i]), float(times[i + 1])) for i in np.flatnonzero(steps > max_gap))
    return sorted(found, key=lambda gap: (gap[1], gap[2]))


def parts_between(found: list[tuple[str, float, float]]) -> list[tuple[float, float]]:
    """The time spans (start, end) left between the gaps (`gaps`' result): the first starts at
    -inf, the last ends at +inf; overlapping gaps make one break."""
    parts, start = [], -np.inf
    for _name, before, after in found:
        if before >= start:
            parts.append((start, before))
            start = after
        else:  # a gap that began inside the previous one
            start = max(start, after)
    parts.append((start, np.inf))
    return parts
