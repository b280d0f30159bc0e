"""Recoveries from a missed grasp (`so101-learn demos --missed-grasps FRACTION`): in that share of
the episodes the expert is told the cube lies a few centimetres from where it is and grasps there:
its jaws shut on nothing (told too far along their travel), or a jaw lands on the cube (told beside
it), and it grasps again where the cube really is (the planner's own regrasp: so101_core::expert).
Told nearer the base, its fixed jaw may push the cube into the grasp and hold it: nothing is kept
then. The dataset keeps the episode from the regrasp on: its first frame shows the arm beside the
cube with its jaws shut or open on it, its actions the way back (up, open, over the cube, down,
shut) and the rest of the task.

Why: camera policies place their first grasp 2-3 cm off more often than the expert does, and then
wait with empty jaws (`so101-bench grasps`, docs/benchmarks.md): the expert's own demonstrations
rarely show a second grasp (about one in seven), and never from a miss that large. The frames of
the deliberate miss itself are left out: they would teach the policy to reach beside the cube.
"""

from __future__ import annotations

import numpy as np

# How far from the cube the told pose is (m, uniform), in a direction drawn uniformly: the camera
# policies' first closings landed 1.7-7.4 cm from the cube, half of them within 2-3 cm.
OFFSET_RANGE = (0.02, 0.035)


def check_fraction(fraction: float) -> float:
    """`fraction` if it is a share of episodes (0 to 1), else ValueError."""
    if not (np.isfinite(fraction) and 0.0 <= fraction <= 1.0):
        raise ValueError(f"--missed-grasps {fraction}: a share of the episodes, from 0 to 1")
    return fraction


def draw_offset(fraction: float, seed: int, episode: int) -> np.ndarray | None:
    """The horizontal offset (m, x and y of the world) of the cube's pose the expert is told
    in this episode, or None when it is told the truth. Depends on the seed and the episode alone,
    not on how episodes are shared among workers."""
    rng = np.random.default_rng((seed, episode, 0x6D155))
    if rng.random() >= fraction:
        return None
    radius = rng.uniform(*OFFSET_RANGE)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    return radius * np.array([np.cos(angle), np.sin(angle)])


def told(observation: dict, offset: np.ndarray) -> dict:
    """`observation` with the cube's position moved by `offset` (x, y), for the expert's plan."""
    state = np.array(observation["environment_state"], dtype=np.float64, copy=True)
    state[:2] += offset
    return {**observation, "environment_state": state}


def recovery_start(regrasps: list[int]) -> int | None:
    """The first frame whose action is the regrasp's (the expert's regrasp count per frame), or
    None when the expert never grasped again (the told grasp held the cube)."""
    return next((k for k, count in enumerate(regrasps) if count > 0), None)


def from_frame(frames: dict[str, list], start: int) -> dict[str, list]:
    """The episode's frames from `start` on."""
    return {name: values[start:] for name, values in frames.items()}
