"""Joint units: the topic contract speaks radians (REP-103); LeRobot's SO-101 datasets use degrees
for the five arm joints and 0-100 for the gripper (0 closed, 100 open)."""

from __future__ import annotations

import math

import numpy as np

from . import contract

JOINT_NAMES = list(contract.JOINT_NAMES)
# LeRobot's feature names for state and action.
FEATURE_NAMES = [f"{name}.pos" for name in JOINT_NAMES]
# Joint limits (rad) of the robot model, shared by the sim and the driver, in contract order.
JOINT_LIMITS = np.array(contract.JOINT_LIMITS)
# The gripper's range in the stack (the model's limits, shared by sim and driver), rad.
GRIPPER_CLOSED, GRIPPER_OPEN = contract.JOINT_LIMITS[-1]


def six_finite(values, what: str) -> np.ndarray:
    """`values` as six finite float64s (an action), else ValueError saying they should be `what`."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if values.shape != (6,) or not np.all(np.isfinite(values)):
        raise ValueError(f"an action is six finite {what}, not {values}")
    return values


def gripper_percent(radians):
    """The gripper's joint (rad) -> its position in its range as 0-100 (LeRobot's RANGE_0_100)."""
    return (radians - GRIPPER_CLOSED) / (GRIPPER_OPEN - GRIPPER_CLOSED) * 100.0


def gripper_radians(percent):
    """The inverse of gripper_percent."""
    return GRIPPER_CLOSED + percent / 100.0 * (GRIPPER_OPEN - GRIPPER_CLOSED)


def lerobot_from_radians(positions: np.ndarray) -> np.ndarray:
    """[..., 6] radians in contract order -> LeRobot units: degrees for the arm (LeRobot's DEGREES
    mode, the same numbers LeRobot records from a calibrated arm), the gripper's position in its
    range as 0-100 (RANGE_0_100)."""
    positions = np.asarray(positions, dtype=np.float64)
    out = np.degrees(positions)
    out[..., 5] = gripper_percent(positions[..., 5])
    return out


def radians_from_lerobot(values: np.ndarray) -> np.ndarray:
    """The inverse of lerobot_from_radians."""
    values = np.asarray(values, dtype=np.float64)
    out = np.radians(values)
    out[..., 5] = gripper_radians(values[..., 5])
    return out


assert math.isclose(float(lerobot_from_radians(np.array([0, 0, 0, 0, 0, GRIPPER_OPEN]))[5]), 100.0)
