"""LeRobot env type `so101_sim`: the simulated task for lerobot-eval and lerobot-train
(`--env.type=so101_sim`), registered when LeRobot imports the plugin distribution
lerobot_env_so101_sim (docs/lerobot.md).

The config builds LeRobot's feature maps (`agent_pos` -> observation.state, `environment_state` ->
observation.environment_state, `pixels/<camera>` -> observation.images.<camera>) and names the
Gymnasium ids registered here, `lerobot_env_so101_sim/<task>` for every task of
so101.contract.TASKS (episode length and task text from its facts), whose environment is
so101.lerobot.adapter.So101LeRobotEnv. Cheap to import (no rclpy): LeRobot imports every plugin at
the start of each of its CLIs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from .. import contract
from ..ee import ACTION_SPACES
from ..sim_options import DEFAULT_SERVO_MODEL, camera_poses_spec, randomize_spec, servo_params_spec

PACKAGE = "lerobot_env_so101_sim"
EE_STATE = "observation.ee_state"
ENVIRONMENT_STATE_SIZE = 7  # cube position (x y z, m) and orientation (w x y z), world frame


def gym_id_of(task: str) -> str:
    return f"{PACKAGE}/{task}"


def register_envs() -> None:
    """Registers `lerobot_env_so101_sim/<task>` for every task of the contract (importing this
    module does), each `--env.episode_length` steps unless told: the task's episode_steps."""
    for task in contract.TASKS.values():
        if gym_id_of(task.name) not in gym.registry:
            gym.register(
                gym_id_of(task.name),
                entry_point="so101.lerobot.adapter:So101LeRobotEnv",
                kwargs={"task": task.name},
                max_episode_steps=task.episode_steps,
            )


def features_of(
    cameras: dict[str, tuple[int, int]], environment_state: bool, action_space: str = "joint"
) -> tuple[dict[str, PolicyFeature], dict[str, str]]:
    """(features, features_map) of the env's observations and action, like LeRobot's own envs;
    with action_space="ee", the end-effector state too (observation.ee_state, as the converter's
    --action-space ee writes it)."""
    features = {
        ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(len(contract.JOINT_NAMES),)),
        "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(len(contract.JOINT_NAMES),)),
    }
    features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
    if environment_state:
        features["environment_state"] = PolicyFeature(type=FeatureType.ENV, shape=(ENVIRONMENT_STATE_SIZE,))
        features_map["environment_state"] = OBS_ENV_STATE
    if action_space == "ee":
        features["ee_state"] = PolicyFeature(type=FeatureType.STATE, shape=(len(contract.EE_NAMES),))
        features_map["ee_state"] = EE_STATE
    for name, (height, width) in cameras.items():
        features[f"pixels/{name}"] = PolicyFeature(type=FeatureType.VISUAL, shape=(height, width, 3))
        features_map[f"pixels/{name}"] = f"{OBS_IMAGES}.{name}"
    return features, features_map


@EnvConfig.register_subclass("so101_sim")
@dataclass
class So101SimEnvConfig(EnvConfig):
    """`--env.type=so101_sim`. cameras: name -> (height, width), e.g. `--env.cameras='{top: [48, 64]}'`
    (names and sizes as in the dataset: observation.images.<name>)."""

    task: str | None = "cube_to_bin"
    fps: int = int(contract.CONTROL_RATE)
    episode_length: int | None = None  # steps; None: the task's (contract.TASKS[task].episode_steps)
    cameras: dict[str, tuple[int, int]] = field(default_factory=dict)
    environment_state: bool = True  # observation.environment_state (cube pose), as the converter writes it
    task_description: str | None = None  # the episodes' task text; None: the task's default
    lite: bool = True  # the sim's lite rendering
    backend: str = "inprocess"  # "inprocess" (so101_native) or "ros" (so101_sim_node in lockstep)
    render_camera: str = "top"  # the camera of lerobot-eval's videos (render())
    render_size: tuple[int, int] = (96, 128)  # its (height, width) unless it is one of `cameras`
    servo_params: str = DEFAULT_SERVO_MODEL  # the sim's servo model: sts3215, gain80 or a so101-sysid fit file
    # Domain randomization: true or default (assets/randomization.toml), false or off, or a .toml.
    randomize: str = "off"
    # Where your real cameras stand: so101-camera-align's file (.toml); empty: the scene's cameras.
    camera_poses: str | None = None
    # What the policy's actions are: joint targets, or end-effector targets ("ee": x y z m, pitch
    # roll rad, gripper 0-100, turned into joint targets by the core's IK; so101.ee).
    action_space: str = "joint"

    def __post_init__(self):
        if self.backend not in ("inprocess", "ros"):
            raise ValueError(f"so101_sim: backend {self.backend!r}, not inprocess or ros")
        if self.task not in contract.TASKS:
            raise ValueError(f"so101_sim: task {self.task!r}, not one of {', '.join(contract.TASKS)}")
        if self.action_space not in ACTION_SPACES:
            raise ValueError(f"so101_sim: action_space {self.action_space!r}, not one of {', '.join(ACTION_SPACES)}")
        for name in [*self.cameras, self.render_camera]:
            if name not in contract.CAMERA_NAMES:
                raise ValueError(f"so101_sim: camera {name!r}, not one of {', '.join(contract.CAMERA_NAMES)}")
        self.cameras = {name: (int(h), int(w)) for name, (h, w) in self.cameras.items()}
        # `--env.randomize=true` arrives as a string; one spelling from here on (so101.sim_options).
        self.servo_params = servo_params_spec(self.servo_params)
        self.randomize = randomize_spec(self.randomize)
        self.camera_poses = camera_poses_spec(self.camera_poses)
        self.features, self.features_map = features_of(self.cameras, self.environment_state, self.action_space)

    @property
    def package_name(self) -> str:
        return PACKAGE

    @property
    def gym_id(self) -> str:
        return gym_id_of(self.task)

    @property
    def gym_kwargs(self) -> dict:
        kwargs = {
            "cameras": dict(self.cameras),
            "fps": self.fps,
            "environment_state": self.environment_state,
            "task_description": self.task_description or contract.TASKS[self.task].description,
            "lite": self.lite,
            "render_camera": self.render_camera,
            "render_size": tuple(self.render_size),
            "backend": self.backend,
            "servo_params": self.servo_params,
            "randomize": self.randomize,
            "camera_poses": self.camera_poses,
            "action_space": self.action_space,
        }
        if self.episode_length:
            kwargs["max_episode_steps"] = int(self.episode_length)
        return kwargs


register_envs()
