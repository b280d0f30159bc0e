"""End-effector (Cartesian) actions and states: so101_core::ee_action through so101_native, shared by
the Gym envs, the LeRobot env and robot types, so101-run-policy and the converter.

An end-effector action or state is, in contract.EE_NAMES order: the grasp point's x, y, z in the
arm's base frame (m), the approach pitch and the jaws' roll (rad; the roll continuous over
wrist_roll's range, not wrapped at +-pi), and the gripper's joint. The stack speaks radians for the
gripper; LeRobot-facing values (datasets, the env and robot types, policies) give it in LeRobot's
0-100, as for joint actions (so101.units). Each period the core's IK turns the target into joint
targets, starting from the targets in force so the arm stays on its branch and moves least; a
target the arm cannot reach becomes the nearest pose it reaches, and the step says so.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from . import contract
from .units import JOINT_LIMITS, gripper_percent, gripper_radians, six_finite

EE_NAMES = list(contract.EE_NAMES)
# LeRobot's feature names of an end-effector action or state (dataset columns, robot features).
EE_FEATURE_NAMES = [f"ee.{name}" for name in EE_NAMES]
ACTION_SPACES = ("joint", "ee")
GRIPPER = 5  # the gripper's index in a joint vector and in an end-effector one


def checked_action_space(action_space: str) -> str:
    if action_space not in ACTION_SPACES:
        raise ValueError(f"action_space {action_space!r}: one of {', '.join(ACTION_SPACES)}")
    return action_space


def ee_poses(joints) -> np.ndarray:
    """The end-effector state of joint positions ([..., 6] rad), [..., 6]."""
    import so101_native

    joints = np.asarray(joints, dtype=np.float64)
    rows = so101_native.ee_poses(np.ascontiguousarray(joints.reshape(-1, 6)))
    return rows.reshape(joints.shape)


def lerobot_ee_from_ee(values) -> np.ndarray:
    """End-effector values with the gripper in rad -> LeRobot's (gripper 0-100, as
    units.lerobot_from_radians gives it); the rest as is."""
    values = np.array(values, dtype=np.float64)
    values[..., GRIPPER] = gripper_percent(values[..., GRIPPER])
    return values


def ee_from_lerobot_ee(values) -> np.ndarray:
    """The inverse of lerobot_ee_from_ee."""
    values = np.array(values, dtype=np.float64)
    values[..., GRIPPER] = gripper_radians(values[..., GRIPPER])
    return values


@functools.cache
def ee_limits() -> np.ndarray:
    """[6, 2] bounds of the end-effector coordinates over the joint limits: the position's box
    (sampled over the joint space, 1 cm of margin), pitch +-pi, the roll wrist_roll's range
    gives, the gripper's joint limits."""
    rng = np.random.default_rng(0)
    joints = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], size=(20000, 6))
    corners = np.array(JOINT_LIMITS).T  # each joint at both of its limits: the roll's extremes
    poses = ee_poses(np.vstack([joints, corners]))
    limits = np.column_stack([poses.min(axis=0), poses.max(axis=0)])
    limits[:3] += [-0.01, 0.01]
    limits[3] = (-np.pi, np.pi)
    limits[GRIPPER] = JOINT_LIMITS[GRIPPER]
    return limits


def checked_ee_action(action) -> np.ndarray:
    return six_finite(action, f"end-effector coordinates ({', '.join(EE_NAMES)})")


@dataclass(frozen=True)
class EeSteps:
    """What end-effector targets command, one row per arm: joint targets (rad, inside the
    limits), whether each target was out of reach (clamped to the nearest reachable pose), and
    how far the commanded pose is from it (m; rad, the larger of pitch and roll)."""

    targets: np.ndarray  # [N, 6]
    clamped: np.ndarray  # [N] bool
    position_error: np.ndarray  # [N]
    angle_error: np.ndarray  # [N]


def joint_targets(targets, in_force) -> EeSteps:
    """Joint targets for end-effector targets ([N, 6], gripper in rad), the IK of each row starting
    from the same row of `in_force` (joint targets, rad)."""
    import so101_native

    targets = np.ascontiguousarray(np.asarray(targets, dtype=np.float64).reshape(-1, 6))
    in_force = np.ascontiguousarray(np.asarray(in_force, dtype=np.float64).reshape(-1, 6))
    return EeSteps(*so101_native.ee_joint_targets(targets, in_force))


class EeCommander:
    """Turns end-effector targets into joint targets period after period for N arms, the IK of
    each starting from that arm's joint targets in force (its measured joints after a reset)."""

    def __init__(self, arms: int = 1):
        self._in_force = np.zeros((arms, 6))

    @property
    def in_force(self) -> np.ndarray:
        """The joint targets the next IK starts from ([N, 6] rad)."""
        return self._in_force.copy()

    def reset(self, joints, arm: int | None = None) -> None:
        """Starts over from measured joints (rad): all arms ([N, 6]), or one ([6])."""
        if arm is None:
            self._in_force = np.array(joints, dtype=np.float64).reshape(self._in_force.shape)
        else:
            self._in_force[arm] = np.asarray(joints, dtype=np.float64)

    def step(self, targets) -> EeSteps:
        """Joint targets for end-effector targets ([N, 6], gripper in rad), which then are in force."""
        steps = joint_targets(np.reshape(targets, self._in_force.shape), self._in_force)
        self._in_force = steps.targets
        return steps
