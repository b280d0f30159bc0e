"""The in-process backend of the Gymnasium environments: the simulation core (crates/so101_sim, the
physics, tasks, rewards and success the sim node runs) stepped through the so101_native extension,
with no ROS and no process to start: seeded resets restart nothing. Both backends give the same
trajectory for the same seed and actions (so101.envs.ros is the other one).

Observations and actions: so101.envs.spaces. Reward: the task's (`dense_reward=True`:
cube_to_bin's staged shaping); terminated when the task succeeds if the task's facts say so
(contract.TASKS[task].terminates_on_success); truncated by max_episode_steps; info["is_success"].
`randomize` (True, False, "default", "off" or a .toml file), `servo_params` (a model's name or a
fit file) and `camera_poses` (so101-camera-align's file): as so101.sim_options reads them.

So101VectorEnv steps N worlds in one native call across threads (a gymnasium VectorEnv with
next-step autoreset), not N processes: what `gym.make_vec(id, num_envs=N)` gives.
"""

from __future__ import annotations

import json
import os

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import contract
from ..paths import asset
from ..sim_options import DEFAULT_SERVO_MODEL, camera_poses_spec, randomize_spec, servo_params_spec
from .spaces import STATE, action_space, checked_action, observation_from_state, observation_space, task_facts


def default_scene() -> str:
    return str(asset("so101_cube_to_bin.xml"))


class So101InProcessEnv(gym.Env):
    """One world of the simulation core, in this process."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": contract.CONTROL_RATE}

    def __init__(
        self,
        task: str = "cube_to_bin",
        control_rate: float | None = None,  # None: the task's
        lite: bool = True,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
        render_mode: str | None = None,
        render_camera: str = "top",
        render_size: tuple[int, int] = (240, 320),
        renderer: str = "auto",
        scene: str | None = None,
        servo_params: str | os.PathLike = DEFAULT_SERVO_MODEL,
        randomize: bool | str | os.PathLike = False,
        camera_poses: str | os.PathLike | None = None,
    ):
        import so101_native

        facts = task_facts(task)
        control_rate = facts.control_rate if control_rate is None else control_rate
        self._terminates_on_success = facts.terminates_on_success
        self._cameras = {name: (int(h), int(w)) for name, (h, w) in (cameras or {}).items()}
        self.render_mode = render_mode
        self._render_camera = render_camera
        self.metadata = {**self.metadata, "render_fps": control_rate}
        self._world = so101_native.World(
            scene or default_scene(),
            lite=lite,
            task=task,
            control_rate=control_rate,
            dense_reward=dense_reward,
            servo_params=servo_params_spec(servo_params),
            randomize=randomize_spec(randomize),
            camera_poses=camera_poses_spec(camera_poses),
        )
        rendered = dict(self._cameras)
        if render_mode == "rgb_array":
            rendered.setdefault(render_camera, tuple(render_size))
        if rendered:
            self._world.enable_cameras(list(rendered.items()), renderer=renderer)
        self._rendered = rendered
        self._frames: dict = {}
        self.observation_space = observation_space(self._cameras)
        self.action_space = action_space()

    def _observe(self):
        state, reward, success = self._world.observe()
        pixels = None
        if self._rendered:
            self._frames = self._world.render()
            pixels = {name: self._frames[name] for name in self._cameras} if self._cameras else None
        return observation_from_state(state, pixels), float(reward), bool(success)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        x, y, yaw = self._world.reset(seed)
        observation, _, success = self._observe()
        settings = json.loads(self._world.episode_settings)
        return observation, {"is_success": success, "cube_start": (x, y, yaw), "episode_settings": settings}

    def step(self, action):
        self._world.step(checked_action(action))
        observation, reward, success = self._observe()
        terminated = success and self._terminates_on_success
        return observation, reward, terminated, False, {"is_success": success}

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return self._frames.get(self._render_camera)

    @property
    def world(self):
        """The so101_native.World underneath (time, efforts, divergences)."""
        return self._world


class So101VectorEnv(VectorEnv):
    """N worlds of the simulation core stepped in one native call across threads, with
    gymnasium's next-step autoreset: the step after an episode ends resets that world (its action
    is ignored) and returns the new episode's first observation."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int,
        task: str = "cube_to_bin",
        max_episode_steps: int | None = None,
        control_rate: float | None = None,  # None: the task's
        lite: bool = True,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
        threads: int = 0,
        renderer: str = "auto",
        scene: str | None = None,
        servo_params: str | os.PathLike = DEFAULT_SERVO_MODEL,
        randomize: bool | str | os.PathLike = False,
        camera_poses: str | os.PathLike | None = None,
        **_ignored,
    ):
        import so101_native

        facts = task_facts(task)
        control_rate = facts.control_rate if control_rate is None else control_rate
        self.num_envs = num_envs
        self._terminates_on_success = facts.terminates_on_success
        self._max_steps = max_episode_steps
        self._cameras = {name: (int(h), int(w)) for name, (h, w) in (cameras or {}).items()}
        self._batch = so101_native.WorldBatch(
            num_envs,
            scene or default_scene(),
            lite=lite,
            task=task,
            control_rate=control_rate,
            dense_reward=dense_reward,
            threads=threads,
            servo_params=servo_params_spec(servo_params),
            randomize=randomize_spec(randomize),
            camera_poses=camera_poses_spec(camera_poses),
        )
        if self._cameras:
            self._batch.enable_cameras(list(self._cameras.items()), renderer=renderer)
        self.single_observation_space = observation_space(self._cameras)
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._needs_reset = np.zeros(num_envs, dtype=bool)

    def _observe(self):
        states, rewards, successes = self._batch.observe()
        observation = {key: np.array(states[:, part]) for key, part in STATE.items()}
        if self._cameras:
            frames = self._batch.render()
            observation["pixels"] = {name: np.stack([world[name] for world in frames]) for name in self._cameras}
        return observation, rewards, successes

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is None:
            self._batch.reset_all(None)
        else:
            seeds = [seed + index for index in range(self.num_envs)] if isinstance(seed, int) else list(seed)
            self._batch.reset_all(seeds)
        self._steps[:] = 0
        self._needs_reset[:] = False
        observation, _, successes = self._observe()
        return observation, {"is_success": successes}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 6)
        if not np.all(np.isfinite(actions)):
            raise ValueError("actions must be finite joint targets (rad)")
        resetting = np.flatnonzero(self._needs_reset)
        for index in resetting:
            self._batch.reset(int(index))
        # A resetting world is not stepped: its action is ignored, as gymnasium's next-step
        # autoreset has it.
        self._batch.step(
            np.ascontiguousarray(actions), active=[not flag for flag in self._needs_reset] if len(resetting) else None
        )
        self._steps += 1
        observation, rewards, successes = self._observe()
        terminated = successes & self._terminates_on_success
        truncated = (self._steps >= self._max_steps) if self._max_steps else np.zeros(self.num_envs, dtype=bool)
        if len(resetting):
            # Next-step autoreset: the resetting worlds report their new episode's start.
            rewards[resetting] = 0.0
            terminated[resetting] = False
            truncated[resetting] = False
            self._steps[resetting] = 0
        self._needs_reset = terminated | truncated
        return observation, rewards, terminated, truncated, {"is_success": successes}

    def close_extras(self, **kwargs):
        self._batch = None
