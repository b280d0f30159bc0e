"""What the robot obeyed: the bag's command messages turned into the sequence of full joint targets
the arm was driven to, by the rules every node that moves an arm applies (so101_core::command,
mirrored here; pure functions, no ROS).

- /joint_commands (sensor_msgs/JointState): joints by name, any subset in any order. Rejected
  whole: names and positions of different lengths, no names, an unknown or a repeated name, a
  non-finite position.
- /forward_position_controller/commands (std_msgs/Float64MultiArray): exactly six values in
  contract order. Rejected whole: another count, a non-finite value.
- An accepted command sets the joints it names, each clamped to its limits; the others keep their
  target (a partial command is merged into the last full target).
- Before the first command the robot holds where it is (the driver holds its measured position;
  the sim holds home, where the arm rests): the joints not yet commanded start from the measured
  joint state at the first command, clamped to the limits.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..units import JOINT_LIMITS, JOINT_NAMES

JOINT_COUNT = len(JOINT_NAMES)


class CommandError(ValueError):
    """A command the nodes reject whole (so101_core::command::CommandError)."""


@dataclass(frozen=True)
class PartialTargets:
    """Targets (rad) of the joints a command names; None for the others, in contract order."""

    targets: tuple[float | None, ...]

    def apply_clamped(self, current: np.ndarray) -> np.ndarray:
        """`current` with the named joints set to their targets clamped to the limits (a copy)."""
        out = np.array(current, dtype=np.float64)
        for joint, value in enumerate(self.targets):
            if value is not None:
                out[joint] = clamp(joint, value)
        return out


def clamp(joint: int, value: float) -> float:
    low, high = JOINT_LIMITS[joint]
    return float(min(max(value, low), high))


def clamped(positions) -> np.ndarray:
    """Six positions clamped to the joint limits."""
    return np.clip(np.asarray(positions, dtype=np.float64), JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])


def _finite(joint: int, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise CommandError(f"position of {JOINT_NAMES[joint]} is not finite ({value})")
    return value


def targets_from_joint_state(names: Sequence[str], positions: Sequence[float]) -> PartialTargets:
    """A /joint_commands message's targets (so101_core::command::targets_from_joint_state)."""
    if len(names) != len(positions):
        raise CommandError(f"command names {len(names)} joints but carries {len(positions)} positions")
    if not names:
        raise CommandError("command carries no positions")
    targets: list[float | None] = [None] * JOINT_COUNT
    for name, value in zip(names, positions):
        if name not in JOINT_NAMES:
            raise CommandError(f"unknown joint name {name!r} (expected one of {JOINT_NAMES})")
        joint = JOINT_NAMES.index(name)
        if targets[joint] is not None:
            raise CommandError(f"joint {name!r} is named twice")
        targets[joint] = _finite(joint, value)
    return PartialTargets(tuple(targets))


def targets_from_array(values: Sequence[float]) -> PartialTargets:
    """A /forward_position_controller/commands message's targets (targets_from_array)."""
    if len(values) != JOINT_COUNT:
        raise CommandError(
            f"array command has {len(values)} values, expected {JOINT_COUNT} (one per joint in order {JOINT_NAMES})"
        )
    return PartialTargets(tuple(_finite(joint, value) for joint, value in enumerate(values)))


def obeyed_targets(commands: Iterable[PartialTargets], start: np.ndarray) -> list[np.ndarray]:
    """The full target after each accepted command, in order, from the held position `start`
    (clamped: the robot never holds a target beyond its limits)."""
    current = clamped(start)
    out = []
    for command in commands:
        current = command.apply_clamped(current)
        out.append(current)
    return out
