"""Disturbances injected into the expert's demonstrations (`so101-learn demos --perturb SIGMA`),
in the manner of DART (Laskey et al., 2017): the arm is pushed off the expert's path while the
dataset records the expert's own, undisturbed targets, so a cloned policy sees states next to
the ones the expert visits and is shown how to come back from them.

A camera policy needs those states most near the cube: where its own first centimetres of error
put the gripper, the demonstrations otherwise never are, and what it learns there (the cube's
place read from the arm's pose, the expert's prior) does not hold.

Each disturbance is one smooth bump of a joint-space offset: sin^2 over BUMP_SECONDS, its
amplitude drawn per joint (SIGMA rad, scaled by JOINT_WEIGHTS), a pause of PAUSE_SECONDS drawn
between bumps. A bump starts only while the expert's jaws are open (before the grasp closes and
after the release), so the grasp and the carry are left as the expert plays them; one in
progress runs out. The planner waits at its gates for the arm it observes, so it does not close
on a cube the arm has been pushed away from.
"""

from __future__ import annotations

import numpy as np

from .. import contract

# The upper arm's joints move the gripper the most; the wrist's roll and the jaws are left alone
# (a turned jaw or a jaw that moves knocks the cube, and teaches nothing about where it is).
JOINT_WEIGHTS = (1.0, 1.0, 1.0, 0.5, 0.0, 0.0)
BUMP_SECONDS = 1.0
PAUSE_SECONDS = (0.3, 1.2)


GRIPPER = contract.JOINT_NAMES.index("gripper")
LOW, HIGH = np.asarray(contract.JOINT_LIMITS, dtype=np.float64).T


def check_sigma(sigma: float) -> float:
    """`sigma` if it is an amplitude a perturbation takes (finite, >= 0 rad), else ValueError."""
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"--perturb {sigma}: a finite amplitude >= 0 (rad)")
    return sigma


def jaws_open_above() -> float:
    """The gripper target above which the expert's jaws count as open: nearer its open value than
    its closed one."""
    import so101_native

    return 0.5 * (so101_native.EXPERT_GRIPPER_OPEN + so101_native.EXPERT_GRIPPER_CLOSED)


class Perturbation:
    """The offset added to the expert's targets, one control period at a time (rad)."""

    def __init__(self, sigma: float, seed: int | tuple[int, ...], control_rate: float = contract.CONTROL_RATE):
        self.sigma = check_sigma(sigma)
        self._jaws_open_above = jaws_open_above()
        self._rng = np.random.default_rng(seed)
        self._period = 1.0 / control_rate
        self._bump_steps = max(1, round(BUMP_SECONDS * control_rate))
        self._amplitude = np.zeros(len(contract.JOINT_NAMES))
        self._step = self._bump_steps  # no bump in progress
        self._pause = self._draw_pause()

    def _draw_pause(self) -> int:
        return round(self._rng.uniform(*PAUSE_SECONDS) / self._period)

    def offset(self, target: np.ndarray) -> np.ndarray:
        """The offset for this period, given the expert's undisturbed target (rad)."""
        if self._step < self._bump_steps:
            self._step += 1
            phase = self._step / self._bump_steps
            return self._amplitude * np.sin(np.pi * phase) ** 2
        if self._pause > 0:
            self._pause -= 1
            return np.zeros_like(self._amplitude)
        if self.sigma > 0 and target[GRIPPER] > self._jaws_open_above:
            self._amplitude = self._rng.normal(0.0, self.sigma, len(JOINT_WEIGHTS)) * np.asarray(JOINT_WEIGHTS)
            self._step = 0
            self._pause = self._draw_pause()
        return np.zeros_like(self._amplitude)

    def __call__(self, target: np.ndarray, observation: dict | None = None) -> np.ndarray:
        """The target to execute: the expert's, pushed by this period's offset, inside the joints'
        limits (float32, as the env takes it). The observation is not read: the push is blind."""
        pushed = np.asarray(target, dtype=np.float64) + self.offset(target)
        return np.clip(pushed, LOW, HIGH).astype(np.float32)
