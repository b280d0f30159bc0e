"""A trained policy driving the expert's demonstrations (`so101-learn demos --driver CKPT`), in the
manner of DAgger (Ross et al., 2011): the arm goes where the policy sends it, the dataset records
the expert's targets from the states it lands in, so the next training run learns what to do where
its policy's own errors take the arm, and, for pose_act, the cube's pose at those frames.

Why beside --perturb (DART, so101.learn.perturbation): noise pushes the arm where a policy might
go; the policy shows where it does go. pose_act's estimator was a few millimetres off on
demonstration frames and over 20 cm off where its own policy took the gripper
(`so101-bench pose_estimate`, docs/benchmarks.md): those states are what its dataset lacked.

--driver-share A blends the two: the arm is sent the expert's target plus A times the policy's
difference from it (1: the policy alone, classic DAgger's rollouts; 0: the expert alone). The
expert's planner waits at its gates for the arm it observes, so its targets stay a path back to
the task from wherever the policy took the arm.
"""

from __future__ import annotations

import numpy as np

from .. import contract

LOW, HIGH = np.asarray(contract.JOINT_LIMITS, dtype=np.float64).T


def check_share(share: float) -> float:
    """`share` if the policy's share of the executed target is one (0 to 1), else ValueError."""
    if not (np.isfinite(share) and 0.0 <= share <= 1.0):
        raise ValueError(f"--driver-share {share}: a share of the policy's target between 0 and 1")
    return share


def blended(expert_target: np.ndarray, policy_target: np.ndarray, share: float) -> np.ndarray:
    """The target the arm is sent: the expert's moved `share` of the way to the policy's, inside
    the joints' limits (float32, as the env takes it)."""
    expert_target = np.asarray(expert_target, dtype=np.float64)
    executed = expert_target + share * (np.asarray(policy_target, dtype=np.float64) - expert_target)
    return np.clip(executed, LOW, HIGH).astype(np.float32)


class PolicyDriver:
    """A policy (so101.evaluate.StackPolicy's interface) choosing where the arm goes, one control
    period at a time, from the observation the expert sees."""

    def __init__(self, policy, share: float):
        self.policy, self.share = policy, check_share(share)

    def reset(self) -> None:
        """Before each episode."""
        self.policy.reset()

    def __call__(self, expert_target: np.ndarray, observation: dict) -> np.ndarray:
        """The target to execute this period, given the expert's and the env's observation."""
        cube = observation.get("environment_state") if self.policy.needs_environment_state else None
        joints = np.asarray(observation["agent_pos"], dtype=np.float64)
        proposed = self.policy.act(self.policy.observation(joints, observation.get("pixels", {}), cube))
        return blended(expert_target, proposed, self.share)


def load_driver(checkpoint: str, share: float, cameras: dict[str, tuple[int, int]]) -> PolicyDriver:
    """The PolicyDriver of a LeRobot checkpoint, given the cameras the demonstrations record
    (PolicyError if it cannot drive with them)."""
    from ..evaluate.policy import PolicyError, StackPolicy

    policy = StackPolicy(checkpoint)
    missing = [camera.name for camera in policy.cameras if camera.name not in cameras]
    if missing:
        raise PolicyError(f"{checkpoint} sees the cameras {', '.join(missing)}: record them (--cameras)")
    return PolicyDriver(policy, share)
