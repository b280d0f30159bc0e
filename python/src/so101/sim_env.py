"""The Gymnasium environments of the SO-101 tasks, in-process by default: `so101/CubeToBin-v0`,
`so101/TouchCube-v0`, `so101/TouchCubeSparse-v0` (the sim node's three tasks), registered by
`import so101`.

The in-process backend steps the simulation core (crates/so101_sim, the physics, tasks, rewards and
success the sim node runs) through the so101_native extension, with no ROS and no process to
start: seeded resets restart nothing. `backend="ros"` runs the same tasks on so101_sim_node in
lockstep over ROS (so101.gym_env), for full-stack runs; both give the same trajectory for the
same seed and actions (tests/integration/test_sim_parity.py).

Observation (a dict): "agent_pos" float64[6] joint positions (rad), "agent_vel" float64[6] joint
velocities (rad/s), "environment_state" float64[7] cube position (m, world frame) and
orientation (w x y z), "pixels" {camera: uint8[H, W, 3]} with `cameras={"top": (H, W), ...}`.
Action: float32[6] joint position targets (rad), clamped to the joint limits. Reward: the task's
(`dense_reward=True`: cube_to_bin's staged shaping); terminated when cube_to_bin succeeds;
truncated by max_episode_steps; info["is_success"].

`gym.make_vec(id, num_envs=N)` steps N worlds in one native call across threads
(So101VectorEnv, a gymnasium VectorEnv with next-step autoreset), not N processes.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .paths import asset
from .units import JOINT_LIMITS

# env id -> (task, steps of an episode)
TASKS = {
    "so101/CubeToBin-v0": ("cube_to_bin", 600),
    "so101/TouchCube-v0": ("touch_cube", 300),
    "so101/TouchCubeSparse-v0": ("touch_cube_sparse", 300),
}
STATE = {"agent_pos": slice(0, 6), "agent_vel": slice(6, 12), "environment_state": slice(12, 19)}
CONTROL_RATE = 30.0


def default_scene() -> str:
    return str(asset("so101_cube_to_bin.xml"))


def observation_space(cameras: dict[str, tuple[int, int]]) -> spaces.Dict:
    space = {
        "agent_pos": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float64),
        "agent_vel": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float64),
        "environment_state": spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64),
    }
    if cameras:
        space["pixels"] = spaces.Dict(
            {name: spaces.Box(0, 255, shape=(h, w, 3), dtype=np.uint8) for name, (h, w) in cameras.items()}
        )
    return spaces.Dict(space)


def action_space() -> spaces.Box:
    return spaces.Box(JOINT_LIMITS[:, 0].astype(np.float32), JOINT_LIMITS[:, 1].astype(np.float32), dtype=np.float32)


def observation_from_state(state: np.ndarray, pixels: dict | None) -> dict:
    """The dict observation from the 19-vector (joints, velocities, cube pose) and the frames."""
    observation = {key: np.array(state[part], dtype=np.float64) for key, part in STATE.items()}
    if pixels is not None:
        observation["pixels"] = pixels
    return observation


def checked_action(action) -> np.ndarray:
    action = np.asarray(action, dtype=np.float64).reshape(-1)
    if action.shape != (6,) or not np.all(np.isfinite(action)):
        raise ValueError(f"an action is six finite joint targets (rad), not {action}")
    return action


class So101InProcessEnv(gym.Env):
    """One world of the simulation core, in this process."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": CONTROL_RATE}

    def __init__(
        self,
        task: str = "cube_to_bin",
        control_rate: float = CONTROL_RATE,
        lite: bool = True,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
        render_mode: str | None = None,
        render_camera: str = "top",
        render_size: tuple[int, int] = (240, 320),
        renderer: str = "auto",
        scene: str | None = None,
    ):
        import so101_native

        self._task = task
        self._cameras = {name: (int(h), int(w)) for name, (h, w) in (cameras or {}).items()}
        self.render_mode = render_mode
        self._render_camera = render_camera
        self.metadata = {**self.metadata, "render_fps": control_rate}
        self._world = so101_native.World(
            scene or default_scene(), lite=lite, task=task, control_rate=control_rate, dense_reward=dense_reward
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
        return observation, {"is_success": success, "cube_start": (x, y, yaw)}

    def step(self, action):
        self._world.step(checked_action(action))
        observation, reward, success = self._observe()
        terminated = success and self._task == "cube_to_bin"
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
        control_rate: float = CONTROL_RATE,
        lite: bool = True,
        cameras: dict[str, tuple[int, int]] | None = None,
        dense_reward: bool = False,
        threads: int = 0,
        renderer: str = "auto",
        scene: str | None = None,
        **_ignored,
    ):
        import so101_native

        self.num_envs = num_envs
        self._task = task
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
        terminated = successes & (self._task == "cube_to_bin")
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


def make_env(task: str = "cube_to_bin", backend: str = "inprocess", **kwargs) -> gym.Env:
    """The env of `task` on `backend` ("inprocess" or "ros")."""
    if backend == "inprocess":
        return So101InProcessEnv(task=task, **kwargs)
    if backend == "ros":
        from .gym_env import So101SimEnv

        return So101SimEnv(task=task, **kwargs)
    raise ValueError(f"backend {backend!r}: 'inprocess' or 'ros'")


def make_vector_env(num_envs: int, task: str = "cube_to_bin", backend: str = "inprocess", **kwargs) -> VectorEnv:
    """make_vec's entry point: the native batch in-process; one ROS env per world otherwise."""
    if backend == "inprocess":
        return So101VectorEnv(num_envs, task=task, **kwargs)
    steps = kwargs.pop("max_episode_steps", None)
    return gym.vector.SyncVectorEnv(
        [lambda: gym.wrappers.TimeLimit(make_env(task, backend, **kwargs), steps) if steps else make_env(task, backend, **kwargs)]
        * num_envs
    )


def register_envs() -> None:
    """Registers the environments (`import so101` does)."""
    for env_id, (task, steps) in TASKS.items():
        if env_id not in gym.registry:
            gym.register(
                env_id,
                entry_point="so101.sim_env:make_env",
                vector_entry_point="so101.sim_env:make_vector_env",
                kwargs={"task": task},
                max_episode_steps=steps,
            )
