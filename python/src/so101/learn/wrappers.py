"""Gymnasium wrappers that put the stack's in-process envs (so101.envs) into the shape
Stable-Baselines3 and `imitation` expect: one flat Box observation and actions in [-1, 1].

Flat observation (float32[19]), in this order: agent_pos (6 joint positions, rad), agent_vel (6 joint
velocities, rad/s), environment_state (7: cube position in m, orientation w x y z); with the phase
cue, a 20th: the episode's elapsed time (s, ElapsedTime). Why the time: the scripted expert follows
timed waypoints and holds still at some of them (opening the gripper above the cube, say), so
one state is followed by "wait" in one instant and "go" in the next; a policy of the state alone
averages the two and stops there for good. Optionally standardized, (x - shift) / scale with the
demonstrations' statistics (bc): the cube's position varies by centimetres, which an MLP resolves
far better in units of its spread.

Relative actions: action in [-1, 1]^6, times `max_step` (rad per control period), added to the
current joint positions, clipped to the joint limits: the env's absolute joint targets. Why not
absolute targets: a single-step policy imitating them learns target ~= current position (the
expert's targets are never far from it) and the arm stalls; deltas make the motion itself the
thing to learn. The default max step, 0.1 rad, is the scripted expert's own per-period limit.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import contract
from ..envs import make_env

# The flat observation's parts, in order; "elapsed" follows when the phase cue is on.
FLAT_KEYS = ("agent_pos", "agent_vel", "environment_state")
ELAPSED = "elapsed"
MAX_STEP = 0.1
# Written beside every policy so101-learn bc / sac saves: the algorithm, the model's file and the
# EnvSettings it was trained with (so101-learn eval rebuilds the same env from it).
SETTINGS_FILE = "so101_learn.json"
# task -> steps of an episode (the registered envs' TimeLimit).
EPISODE_STEPS = {name: task.episode_steps for name, task in contract.TASKS.items()}


def flatten(observation: dict, keys=FLAT_KEYS) -> np.ndarray:
    """The dict observation's `keys`, in that order, as one float32 vector (pixels left out)."""
    return np.concatenate([np.asarray(observation[key], dtype=np.float32).reshape(-1) for key in keys])


def relative_action(target, positions, max_step) -> np.ndarray:
    """The action in [-1, 1]^6 that moves towards absolute joint `target` from `positions` (what
    demonstrations in absolute targets become); clipped where the target is more than a max step away."""
    delta = (np.asarray(target, dtype=np.float64) - np.asarray(positions, dtype=np.float64)) / max_step
    return np.clip(delta, -1.0, 1.0).astype(np.float32)


class ElapsedTime(gym.Wrapper):
    """Adds observation["elapsed"], float64[1]: seconds since the reset (steps / control rate)."""

    def __init__(self, env: gym.Env, control_rate: float = contract.CONTROL_RATE):
        super().__init__(env)
        self.observation_space = spaces.Dict(
            {**env.observation_space.spaces, ELAPSED: spaces.Box(0.0, np.inf, shape=(1,), dtype=np.float64)}
        )
        self._period = 1.0 / control_rate
        self._steps = 0

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        self._steps = 0
        return {**observation, ELAPSED: np.zeros(1)}, info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        return {**observation, ELAPSED: np.array([self._steps * self._period])}, reward, terminated, truncated, info


class FlatObservation(gym.ObservationWrapper):
    """The dict observation's `keys` as one float32 vector (see flatten), standardized as
    (x - shift) / scale when those are given."""

    def __init__(self, env: gym.Env, keys=FLAT_KEYS, shift=None, scale=None):
        super().__init__(env)
        self.keys = tuple(keys)
        size = sum(int(np.prod(env.observation_space[key].shape)) for key in self.keys)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        self.shift = np.zeros(size, np.float32) if shift is None else np.asarray(shift, np.float32)
        self.scale = np.ones(size, np.float32) if scale is None else np.asarray(scale, np.float32)

    def observation(self, observation: dict) -> np.ndarray:
        return (flatten(observation, self.keys) - self.shift) / self.scale


class RelativeJointTargets(gym.Wrapper):
    """Actions in [-1, 1]^6 as joint moves of at most `max_step` rad (one value, or one per joint)
    per control period from the current positions, clipped to the joint limits (the wrapped env's
    action_space). Wraps the dict-observation env: it reads agent_pos."""

    def __init__(self, env: gym.Env, max_step: float | list[float] = MAX_STEP):
        super().__init__(env)
        self.max_step = np.broadcast_to(np.asarray(max_step, dtype=np.float64), (6,)).copy()
        if not np.all(self.max_step > 0):
            raise ValueError(f"max_step must be positive, not {max_step}")
        self._low = env.action_space.low.astype(np.float64)
        self._high = env.action_space.high.astype(np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(6,), dtype=np.float32)
        self._positions: np.ndarray | None = None

    def target(self, action) -> np.ndarray:
        """The absolute joint targets (rad) that `action` means from the current positions."""
        if self._positions is None:
            raise RuntimeError("reset the env before stepping it")
        step = np.clip(np.asarray(action, dtype=np.float64).reshape(6), -1.0, 1.0) * self.max_step
        return np.clip(self._positions + step, self._low, self._high)

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        self._positions = np.array(observation["agent_pos"], dtype=np.float64)
        return observation, info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(self.target(action).astype(np.float32))
        self._positions = np.array(observation["agent_pos"], dtype=np.float64)
        return observation, reward, terminated, truncated, info


@dataclass
class EnvSettings:
    """What a policy was trained on; saved beside it so that evaluation rebuilds the same env."""

    task: str = "cube_to_bin"
    max_step: float | list[float] = MAX_STEP
    dense_reward: bool = False
    episode_steps: int | None = None  # None: the task's registered length
    elapsed_time: bool = False  # the phase cue (ElapsedTime) in the observation
    observation_shift: list[float] | None = None  # FlatObservation's standardization, if any
    observation_scale: list[float] | None = None

    def __post_init__(self):
        if self.task not in EPISODE_STEPS:
            raise ValueError(f"task {self.task!r}: one of {', '.join(EPISODE_STEPS)}")
        self.episode_steps = int(self.episode_steps or EPISODE_STEPS[self.task])

    def make(self, flat: bool = True, cameras: dict[str, tuple[int, int]] | None = None, lite: bool = True) -> gym.Env:
        """The in-process env with relative actions; `flat`: the flat observation and a TimeLimit
        (for SB3); otherwise the dict observation (pixels included), for so101.evaluate.episodes."""
        env = make_env(self.task, lite=lite, cameras=cameras, dense_reward=self.dense_reward)
        env = RelativeJointTargets(env, self.max_step)
        if self.elapsed_time:
            env = ElapsedTime(env)
        if flat:
            env = FlatObservation(env, self.keys, self.observation_shift, self.observation_scale)
            env = gym.wrappers.TimeLimit(env, self.episode_steps)
        return env

    @property
    def keys(self) -> tuple[str, ...]:
        """The flat observation's parts, in order."""
        return (*FLAT_KEYS, ELAPSED) if self.elapsed_time else FLAT_KEYS

    def flat(self, observation: dict) -> np.ndarray:
        """flatten(observation), standardized as FlatObservation does (for dict-observation envs)."""
        flat = flatten(observation, self.keys)
        if self.observation_shift is not None:
            flat = (flat - np.asarray(self.observation_shift, np.float32)) / np.asarray(self.observation_scale, np.float32)
        return flat

    def to_dict(self) -> dict:
        return {**asdict(self), "observation": list(self.keys), "action": "relative joint targets in [-1, 1]"}

    @classmethod
    def from_dict(cls, values: dict) -> EnvSettings:
        fields = ("task", "max_step", "dense_reward", "episode_steps", "elapsed_time", "observation_shift", "observation_scale")
        return cls(**{key: values[key] for key in fields if key in values})
