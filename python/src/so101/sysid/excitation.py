"""The excitation of one joint: steps up and down (each held, so gravity's sag and the dead zone
show), then a chirp whose frequency rises (so inertia, damping and latency show). Offsets from the
joint's start position, small enough that every goal stays within the driver's --max-step of
where the joint is. Pure."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Excitation:
    amplitude: float = 0.06  # rad, of the steps; the chirp's is 0.6 of it
    hold: float = 0.6  # s each step is held
    chirp_seconds: float = 6.0
    chirp_start_hz: float = 0.5
    chirp_end_hz: float = 6.0
    settle: float = 0.5  # s at the start position, before and after
    rate: float = 100.0  # goals per second

    def offsets(self) -> np.ndarray:
        """(time s, offset rad) rows of the whole excitation, at `rate`."""
        period = 1.0 / self.rate
        rows: list[tuple[float, float]] = []
        time = 0.0

        def hold(offset: float, seconds: float) -> None:
            nonlocal time
            for _ in range(int(round(seconds * self.rate))):
                rows.append((time, offset))
                time += period

        a = self.amplitude
        hold(0.0, self.settle)
        for offset in (a, 0.0, -a, 0.0, 0.5 * a, -0.5 * a, 0.0):
            hold(offset, self.hold)
        sweep = (self.chirp_end_hz - self.chirp_start_hz) / self.chirp_seconds
        for k in range(int(round(self.chirp_seconds * self.rate))):
            t = k * period
            phase = 2 * math.pi * (self.chirp_start_hz * t + 0.5 * sweep * t * t)
            rows.append((time, 0.6 * a * math.sin(phase)))
            time += period
        hold(0.0, self.settle)
        return np.array(rows)

    @property
    def seconds(self) -> float:
        return self.settle * 2 + 7 * self.hold + self.chirp_seconds


def held_out(amplitude: float = 0.05, seconds: float = 6.0, rate: float = 100.0, seed: int = 0) -> np.ndarray:
    """A different motion for checking a fit: a sum of three sines of seeded frequencies
    (0.3-2 Hz) and phases, from and back to zero. (time s, offset rad) rows."""
    rng = np.random.default_rng(seed)
    frequencies = rng.uniform(0.3, 2.0, size=3)
    phases = rng.uniform(0, 2 * math.pi, size=3)
    times = np.arange(int(round(seconds * rate))) / rate
    window = np.sin(math.pi * times / seconds) ** 2  # starts and ends at rest
    motion = sum(np.sin(2 * math.pi * f * times + p) for f, p in zip(frequencies, phases)) / 3
    return np.column_stack([times, amplitude * window * motion])
