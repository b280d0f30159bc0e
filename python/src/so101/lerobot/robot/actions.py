"""A LeRobot action dict -> the joint command of /joint_commands (tested without ROS): joint targets,
or end-effector targets turned into joint targets by the core's IK (so101.ee), then the same
checks, max_relative_target and limits."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...ee import EE_FEATURE_NAMES, ee_from_lerobot_ee, ee_poses, joint_targets, lerobot_ee_from_ee
from ...units import FEATURE_NAMES, JOINT_LIMITS, lerobot_from_radians, radians_from_lerobot


def values_of(action: dict[str, Any], names: list[str], defaults: np.ndarray) -> np.ndarray:
    """The values of `names` in `action` (floats, numpy scalars or 0-d tensors), `defaults` where a
    key is missing or None. A value that is not a finite number raises ValueError naming it."""
    values = np.array(defaults, dtype=np.float64)
    for index, key in enumerate(names):
        value = action.get(key)
        if value is None:
            continue
        try:
            number = float(value)
        except (TypeError, ValueError) as error:
            raise ValueError(f"action {key}={value!r} is not a number") from error
        if not math.isfinite(number):
            raise ValueError(f"action {key}={number} is not finite: nothing sent")
        values[index] = number
    return values


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
    goal = values_of(action, FEATURE_NAMES, lerobot_from_radians(np.asarray(hold, dtype=np.float64)))
    if max_relative_target is not None and present is not None:
        now = lerobot_from_radians(np.asarray(present, dtype=np.float64))
        goal = np.clip(goal, now - max_relative_target, now + max_relative_target)
    radians = np.clip(radians_from_lerobot(goal), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
    sent = lerobot_from_radians(radians)
    return radians, {key: float(value) for key, value in zip(FEATURE_NAMES, sent)}


@dataclass(frozen=True)
class EeCommand:
    """What an end-effector action commands."""

    radians: np.ndarray  # the joint command (rad, contract order)
    sent: dict[str, float]  # the end-effector pose it commands (EE_FEATURE_NAMES, LeRobot units)
    target: np.ndarray  # the end-effector target asked for, missing keys filled (LeRobot units)
    clamped: bool  # the target was out of reach: the nearest reachable pose is commanded


def command_from_ee_action(
    action: dict[str, Any],
    hold: np.ndarray,
    present: np.ndarray | None = None,
    max_relative_target: float | None = None,
    target_in_force: np.ndarray | None = None,
) -> EeCommand:
    """The joint command for an end-effector action dict ("ee.x" ... "ee.gripper": m, rad,
    gripper 0-100; any other key is refused). Missing keys keep `target_in_force` (the last end-effector target asked for;
    default: the pose of `hold`), so a capped step does not become the new target. The IK starts
    from `hold` (the joint targets in force); its joint targets then pass command_from_action's
    checks, `max_relative_target` and limits, as a joint action's would."""
    strangers = sorted(key for key in action if key not in EE_FEATURE_NAMES)
    if strangers:
        raise ValueError(f"action keys {strangers} are not end-effector ones ({', '.join(EE_FEATURE_NAMES)}): nothing sent")
    hold = np.asarray(hold, dtype=np.float64)
    if target_in_force is None:
        target_in_force = lerobot_ee_from_ee(ee_poses(hold))
    target = values_of(action, EE_FEATURE_NAMES, target_in_force)
    steps = joint_targets(ee_from_lerobot_ee(target), hold)
    joints = dict(zip(FEATURE_NAMES, lerobot_from_radians(steps.targets[0])))
    radians, _ = command_from_action(joints, hold, present, max_relative_target)
    sent = lerobot_ee_from_ee(ee_poses(radians))
    return EeCommand(radians, {key: float(value) for key, value in zip(EE_FEATURE_NAMES, sent)}, target, bool(steps.clamped[0]))
