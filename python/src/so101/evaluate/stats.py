"""Statistics the evaluations report: a success rate with its 95 % interval."""

from __future__ import annotations

import math

Z_95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson_interval(successes: int, episodes: int, z: float = Z_95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (as fractions): unlike the normal
    approximation it stays inside [0, 1] and is sound for few episodes or rates near 0 or 1."""
    if episodes <= 0:
        return (0.0, 1.0)
    if not 0 <= successes <= episodes:
        raise ValueError(f"{successes} successes in {episodes} episodes")
    rate = successes / episodes
    denominator = 1 + z * z / episodes
    centre = (rate + z * z / (2 * episodes)) / denominator
    half = z * math.sqrt(rate * (1 - rate) / episodes + z * z / (4 * episodes * episodes)) / denominator
    return (max(0.0, centre - half), min(1.0, centre + half))
