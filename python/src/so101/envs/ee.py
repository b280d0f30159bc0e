"""`action_space="ee"` for the task envs of both backends: the action is an end-effector target
(so101.ee: x y z m in the arm's base frame, pitch and roll rad, the gripper's joint rad), turned
into joint targets by the core's IK each period; the joint targets then go to the env as a joint
action would (the same limits). The observation gains "ee_state" (the end-effector state of the
measured joints) and the info says whether the target was out of reach ("ee_clamped": the
nearest reachable pose was commanded) and by how much ("ee_position_error" m, "ee_angle_error" rad).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

from ..ee import EeCommander, checked_ee_action, ee_limits, ee_poses


def ee_action_space() -> spaces.Box:
    limits = ee_limits()
    return spaces.Box(limits[:, 0].astype(np.float32), limits[:, 1].astype(np.float32), dtype=np.float32)


def with_ee_state(observation_space: spaces.Dict) -> spaces.Dict:
    return spaces.Dict({**observation_space.spaces, "ee_state": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float64)})


def ee_info(steps, arm: int | None = None) -> dict:
    """The info of an end-effector step: one arm's values, or every arm's (arrays) for a vector env."""
    pick = (lambda values: values) if arm is None else (lambda values: values[arm].item())
    return {
        "ee_clamped": pick(steps.clamped),
        "ee_position_error": pick(steps.position_error),
        "ee_angle_error": pick(steps.angle_error),
    }


class EeActionEnv(gym.Wrapper):
    """One task env acting in end-effector space."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.action_space = ee_action_space()
        self.observation_space = with_ee_state(env.observation_space)
        self.commander = EeCommander()

    def _observed(self, observation: dict) -> dict:
        return {**observation, "ee_state": ee_poses(observation["agent_pos"])}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = self.env.reset(seed=seed, options=options)
        self.commander.reset(observation["agent_pos"])
        return self._observed(observation), info

    def step(self, action):
        steps = self.commander.step(checked_ee_action(action))
        observation, reward, terminated, truncated, info = self.env.step(steps.targets[0])
        return self._observed(observation), reward, terminated, truncated, {**info, **ee_info(steps, arm=0)}


class EeActionVectorEnv(VectorWrapper):
    """N task envs (a VectorEnv with next-step autoreset) acting in end-effector space: a world
    that starts a new episode starts its IK over from the new episode's joints."""

    def __init__(self, env: VectorEnv):
        super().__init__(env)
        self.single_action_space = ee_action_space()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.single_observation_space = with_ee_state(env.single_observation_space)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.commander = EeCommander(self.num_envs)
        self._ended = np.zeros(self.num_envs, dtype=bool)

    def _observed(self, observation: dict) -> dict:
        return {**observation, "ee_state": ee_poses(observation["agent_pos"])}

    def reset(self, *, seed=None, options=None):
        observation, info = self.env.reset(seed=seed, options=options)
        self.commander.reset(observation["agent_pos"])
        self._ended[:] = False
        return self._observed(observation), info

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 6)
        if not np.all(np.isfinite(actions)):
            raise ValueError("end-effector actions must be finite (x y z m, pitch roll rad, gripper rad)")
        steps = self.commander.step(actions)
        observation, rewards, terminated, truncated, info = self.env.step(steps.targets)
        for arm in np.flatnonzero(self._ended):  # these worlds reset: their new episode's joints
            self.commander.reset(observation["agent_pos"][arm], arm)
        self._ended = np.asarray(terminated) | np.asarray(truncated)
        return self._observed(observation), rewards, terminated, truncated, {**info, **ee_info(steps)}
