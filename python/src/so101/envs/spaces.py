"""What both backends of the Gymnasium environments share: the observation and action spaces, the
dict observation built from the state vector, the action check, and a task's facts (the
generated contract's Task).

Observation (a dict): "agent_pos" float64[6] joint positions (rad), "agent_vel" float64[6] joint
velocities (rad/s), "environment_state" float64[7] cube position (m, world frame) and
orientation (w x y z), "pixels" {camera: uint8[H, W, 3]} with `cameras={"top": (H, W), ...}`.
Action: float32[6] joint position targets (rad), clamped to the joint limits.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from .. import contract
from ..units import JOINT_LIMITS, six_finite

# The parts of the 19-vector the simulation core reports (joints, velocities, cube pose).
STATE = {"agent_pos": slice(0, 6), "agent_vel": slice(6, 12), "environment_state": slice(12, 19)}


def task_facts(task: str) -> contract.Task:
    """The contract's facts of `task` (episode length, termination, control rate, ...)."""
    try:
        return contract.TASKS[task]
    except KeyError:
        raise ValueError(f"task {task!r}: one of {', '.join(contract.TASKS)}") from None


def reward_mode(task: str, dense_reward: bool) -> str:
    """The reward an episode of `task` is scored with: the dense one where asked for and offered,
    else the task's default (its first mode)."""
    modes = task_facts(task).reward_modes
    return "dense" if dense_reward and "dense" in modes else modes[0]


def observation_space(cameras: dict[str, tuple[int, int]]) -> spaces.Dict:
    space = {
        "agent_pos": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float64),
        "agent_vel": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float64),
        "environment_state": spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64),
    }
    if cameras:
        space["pixels"] = spaces.Dict(
            {name: spaces.Box(0, 255, shape=(h, w, 3), dtype=np.uint8) for name, (h, w) in cameras.items()}
        )
    return spaces.Dict(space)


def action_space() -> spaces.Box:
    return spaces.Box(JOINT_LIMITS[:, 0].astype(np.float32), JOINT_LIMITS[:, 1].astype(np.float32), dtype=np.float32)


def observation_from_state(state: np.ndarray, pixels: dict | None) -> dict:
    """The dict observation from the 19-vector (joints, velocities, cube pose) and the frames."""
    observation = {key: np.array(state[part], dtype=np.float64) for key, part in STATE.items()}
    if pixels is not None:
        observation["pixels"] = pixels
    return observation


def checked_action(action) -> np.ndarray:
    return six_finite(action, "joint targets (rad)")
