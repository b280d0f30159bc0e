"""The end-effector columns of a converted episode (--action-space ee; so101.ee): the action becomes
the end-effector target the joint command reaches (the forward kinematics of the joint targets:
x y z m in the arm's base frame, pitch and roll rad, the gripper in the dataset's joint units) and
observation.ee_state the end-effector state of the measured joints. Also how many of those
targets the IK, replaying them from the joint targets before each, finds out of reach."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..ee import ee_poses, joint_targets, lerobot_ee_from_ee
from ..units import radians_from_lerobot


def to_radians(values: np.ndarray, units: str) -> np.ndarray:
    return radians_from_lerobot(values) if units == "lerobot" else np.asarray(values, dtype=np.float64)


def in_units(ee: np.ndarray, units: str) -> np.ndarray:
    return (lerobot_ee_from_ee(ee) if units == "lerobot" else ee).astype(np.float32)


def ee_columns(state: np.ndarray, action: np.ndarray, units: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(end-effector action, end-effector state, how many of those actions are out of reach) of an
    episode's joint states and joint actions ([N, 6] in `units`), in `units`."""
    state = to_radians(state, units)
    joint_action = to_radians(action, units)
    ee_action = ee_poses(joint_action)
    # Each target replayed as a policy's would be: the IK from the targets in force before it.
    in_force = np.vstack([state[:1], joint_action[:-1]])
    clamped = int(joint_targets(ee_action, in_force).clamped.sum())
    return in_units(ee_action, units), in_units(ee_poses(state), units), clamped


def with_ee_columns(frames, units: str):
    """`frames` (so101.dataset.convert.Frames, joints in `units`) with the end-effector action and
    state, and the number of its actions out of reach."""
    ee_action, ee_state, clamped = ee_columns(frames.state, frames.action, units)
    return replace(frames, action=ee_action, ee_state=ee_state), clamped
