"""The Gymnasium env behind LeRobot's env type `so101_sim` (so101.lerobot.env): the task env of
so101.envs (in-process by default; backend "ros" for so101_sim_node in lockstep) seen the way
LeRobot's envs and the converter's datasets see the robot.

Observation: {"agent_pos": float32[6] joint positions in LeRobot units (degrees, gripper 0-100),
"environment_state": float32[7] cube position (m) and orientation (w x y z), world frame (when
asked), "pixels": {camera: uint8[H, W, 3]} (when cameras are asked)}. Action: float32[6] joint
targets in LeRobot units; with action_space="ee", an end-effector target (so101.ee: x y z m,
pitch roll rad, gripper 0-100) and the observation's "ee_state" the same for the measured joints. info["is_success"]: the sim's /task/success of the step. render(): the
render camera's frame of the last step (rgb_array), enlarged to at least 360 pixels tall (what
lerobot-eval films), at metadata["render_fps"] = fps.
"""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .. import contract
from ..ee import ee_from_lerobot_ee, ee_limits, lerobot_ee_from_ee
from ..envs import make_env
from ..evaluate.episodes import watchable
from ..sim_options import DEFAULT_SERVO_MODEL
from ..units import JOINT_LIMITS, lerobot_from_radians, radians_from_lerobot


def observation_from_sim(sim_observation: dict, cameras, environment_state: bool) -> dict:
    """so101.envs' observation (radians) -> LeRobot's env observation."""
    observation = {"agent_pos": lerobot_from_radians(sim_observation["agent_pos"]).astype(np.float32)}
    if "ee_state" in sim_observation:
        observation["ee_state"] = lerobot_ee_from_ee(sim_observation["ee_state"]).astype(np.float32)
    if environment_state:
        observation["environment_state"] = np.asarray(sim_observation["environment_state"], dtype=np.float32)
    if cameras:
        observation["pixels"] = {name: sim_observation["pixels"][name] for name in cameras}
    return observation


def sim_action_from_lerobot(action, action_space: str = "joint") -> np.ndarray:
    """A LeRobot action (degrees, gripper 0-100; or an end-effector target) -> so101.envs' (radians)."""
    action = np.asarray(action, dtype=np.float64).reshape(-1)
    if action.shape != (6,):
        raise ValueError(f"an so101_sim action is 6 {action_space} targets, not shape {action.shape}")
    return ee_from_lerobot_ee(action) if action_space == "ee" else radians_from_lerobot(action)


class So101LeRobotEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": int(contract.CONTROL_RATE)}

    def __init__(
        self,
        task: str = "cube_to_bin",
        cameras: dict[str, tuple[int, int]] | None = None,
        fps: int = int(contract.CONTROL_RATE),
        environment_state: bool = False,
        task_description: str = "",
        lite: bool = True,
        render_camera: str = "top",
        render_size: tuple[int, int] = (96, 128),
        render_mode: str = "rgb_array",
        backend: str = "inprocess",
        servo_params: str | os.PathLike = DEFAULT_SERVO_MODEL,
        randomize: bool | str | os.PathLike = False,
        camera_poses: str | os.PathLike | None = None,
        action_space: str = "joint",
    ):
        self._action_space = action_space
        self._cameras = {name: tuple(size) for name, size in (cameras or {}).items()}
        self._environment_state = environment_state
        self._render_camera = render_camera
        sim_cameras = dict(self._cameras)
        sim_cameras.setdefault(render_camera, tuple(render_size))
        self._sim = make_env(
            task,
            backend=backend,
            control_rate=float(fps),
            lite=lite,
            cameras=sim_cameras,
            servo_params=servo_params,
            randomize=randomize,
            camera_poses=camera_poses,
            action_space=action_space,
        )
        self.metadata = {**self.metadata, "render_fps": fps}
        self.render_mode = render_mode
        self.task_description = self.task = task_description
        low, high = lerobot_ee_from_ee(ee_limits().T) if action_space == "ee" else lerobot_from_radians(JOINT_LIMITS.T)
        self.action_space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        space = {"agent_pos": spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float32)}
        if environment_state:
            space["environment_state"] = spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float32)
        if action_space == "ee":
            space["ee_state"] = spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float32)
        if self._cameras:
            space["pixels"] = spaces.Dict(
                {name: spaces.Box(0, 255, shape=(h, w, 3), dtype=np.uint8) for name, (h, w) in self._cameras.items()}
            )
        self.observation_space = spaces.Dict(space)
        h, w = sim_cameras[render_camera]
        self._frame = np.zeros((h, w, 3), dtype=np.uint8)

    def _convert(self, sim_observation) -> dict:
        self._frame = sim_observation["pixels"][self._render_camera]
        return observation_from_sim(sim_observation, self._cameras, self._environment_state)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        sim_observation, info = self._sim.reset(seed=seed)
        # The episode's settings (nested JSON) stay out of the info LeRobot's vector envs stack.
        info.pop("episode_settings", None)
        return self._convert(sim_observation), {**info, "is_success": bool(info["is_success"])}

    def step(self, action):
        sim_observation, reward, terminated, truncated, info = self._sim.step(sim_action_from_lerobot(action, self._action_space))
        return self._convert(sim_observation), reward, terminated, truncated, {**info, "is_success": bool(info["is_success"])}

    def render(self) -> np.ndarray:
        return watchable(self._frame)

    def close(self) -> None:
        self._sim.close()
