"""The scripted expert of every task in-process, as a policy over the Gymnasium environments'
observations (so101.envs): demonstrations for behaviour cloning at simulation speed.

It is teleop_node's expert (the planner in so101_core::expert, called through so101_native):
from the settled cube's pose, a grasp from above, then the task's part (cube_to_bin: a lift, a
carry over the bin and a release; lift_cube: a lift, held; the touch tasks: the jaws at the cube), as
timed waypoints turned into joint targets by the shared IK, each target moved at most `max_step`
rad per period. The plan waits at its gates for the arm it observes (the grasp reached, the
gripper closed, the arm over the bin) and goes back up to grasp again (at most twice) when a jaw
lands on the cube or the jaws close on nothing (at the cube's pose of the observation). The noise
options are teleop_node's (--waypoint-noise, --action-noise).

    env = gym.make("so101/CubeToBin-v0")
    expert = ExpertPolicy(waypoint_noise=0.005, action_noise=0.01, seed=1)
    observation, _ = env.reset(seed=0)
    expert.reset(observation)
    while True:
        observation, reward, terminated, truncated, info = env.step(expert(observation))
"""

from __future__ import annotations

import numpy as np

from .. import contract


class ExpertPolicy:
    def __init__(
        self,
        waypoint_noise: float = 0.0,
        action_noise: float = 0.0,
        seed: int = 0,
        max_step: float = 0.1,
        control_rate: float = contract.CONTROL_RATE,
        task: str = "cube_to_bin",
    ):
        import so101_native

        self._expert = so101_native.Expert(
            waypoint_noise=waypoint_noise, action_noise=action_noise, seed=seed, max_step=max_step, task=task
        )
        self._period = 1.0 / control_rate
        self.duration = 0.0

    def reset(self, observation: dict) -> float:
        """Plans the episode from its first observation (the arm's joints, the cube's pose).
        Returns the plan's duration as timed (s: its gates and regrasps may add to it); ValueError
        when no grasp reaches the cube."""
        cube = np.asarray(observation["environment_state"], dtype=np.float64)
        self.duration = self._expert.plan(
            np.asarray(observation["agent_pos"], dtype=np.float64), cube[:3].copy(), cube[3:7].copy()
        )
        return self.duration

    def __call__(self, observation: dict) -> np.ndarray:
        """The joint targets of the next control period (rad, float32[6]) for the arm of
        `observation` (its agent_pos: the plan waits for the arm at its gates)."""
        joints = np.asarray(observation["agent_pos"], dtype=np.float64)
        cube = observation.get("environment_state")
        if cube is None:
            return self._expert.step(joints, self._period).astype(np.float32)
        cube = np.asarray(cube, dtype=np.float64)
        return self._expert.step(joints, self._period, cube[:3].copy(), cube[3:7].copy()).astype(np.float32)

    @property
    def done(self) -> bool:
        """The plan has been played to its end (for cube_to_bin: the cube released over the bin)."""
        return self._expert.finished

    @property
    def regrasps(self) -> int:
        """How many times this episode's plan went back up to grasp again."""
        return self._expert.regrasps
