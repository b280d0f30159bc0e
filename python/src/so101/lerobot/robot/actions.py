"""A LeRobot action dict -> the joint command of /joint_commands (pure: tested without ROS)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...units import FEATURE_NAMES, JOINT_LIMITS, lerobot_from_radians, radians_from_lerobot


def command_from_action(
    action: dict[str, Any], hold: np.ndarray, present: np.ndarray | None = None, max_relative_target: float | None = None
) -> tuple[np.ndarray, dict[str, float]]:
    """The joint command (rad, contract order) for a LeRobot action dict, and the action actually
    sent (LeRobot units, FEATURE_NAMES order).

    `action` maps "<joint>.pos" to LeRobot units (floats, numpy scalars or 0-d tensors); missing
    keys, None values and unknown keys leave a joint at `hold` (rad). With `max_relative_target`,
    each joint's step from `present` (rad) is clamped to that many LeRobot units. The result is
    clipped to the contract's joint limits. A value that is not a finite number raises ValueError
    (naming the joint): nothing is sent for such an action."""
    goal = lerobot_from_radians(np.asarray(hold, dtype=np.float64))
    for index, key in enumerate(FEATURE_NAMES):
        value = action.get(key)
        if value is None:
            continue
        try:
            number = float(value)
        except (TypeError, ValueError) as error:
            raise ValueError(f"action {key}={value!r} is not a number") from error
        if not math.isfinite(number):
            raise ValueError(f"action {key}={number} is not finite: nothing sent")
        goal[index] = number
    if max_relative_target is not None and present is not None:
        now = lerobot_from_radians(np.asarray(present, dtype=np.float64))
        goal = np.clip(goal, now - max_relative_target, now + max_relative_target)
    radians = np.clip(radians_from_lerobot(goal), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
    sent = lerobot_from_radians(radians)
    return radians, {key: float(value) for key, value in zip(FEATURE_NAMES, sent)}
