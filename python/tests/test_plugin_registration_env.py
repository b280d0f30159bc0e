"""The env plugin without a sim: LeRobot's plugin discovery makes `so101_sim` an env type, its
features match the converter's dataset features, and the adapter's conversions are LeRobot's units."""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest
from lerobot.envs.configs import EnvConfig

from so101 import contract, units
from so101.dataset import convert


@dataclass
class EnvHolder:
    """An `env` field parsed as lerobot-eval and lerobot-train parse theirs."""

    env: EnvConfig


def registered_env_config():
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    return EnvConfig.get_choice_class("so101_sim")


def test_plugin_discovery_registers_the_env_type_and_its_gym_ids():
    cls = registered_env_config()
    assert "so101_sim" in EnvConfig.get_known_choices()
    from so101.lerobot.env import So101SimEnvConfig

    assert cls is So101SimEnvConfig
    config = cls()
    assert config.type == "so101_sim" and config.task == "cube_to_bin"
    assert config.package_name == "lerobot_env_so101_sim"
    for task in contract.TASKS:
        spec = gym.spec(cls(task=task).gym_id)
        assert spec.entry_point == "so101.lerobot.adapter:So101LeRobotEnv" and spec.kwargs["task"] == task


def test_the_env_type_parses_from_the_command_line():
    import draccus

    registered_env_config()
    parsed = draccus.parse(
        EnvHolder,
        args=[
            "--env.type=so101_sim",
            "--env.task=touch_cube",
            "--env.episode_length=20",
            "--env.cameras={top: [48, 64]}",
            "--env.environment_state=true",
        ],
    )
    env = parsed.env
    assert env.task == "touch_cube" and env.cameras == {"top": (48, 64)} and env.environment_state
    assert env.gym_kwargs["max_episode_steps"] == 20 and env.gym_kwargs["cameras"] == {"top": (48, 64)}
    assert env.gym_kwargs["task_description"] == "touch the cube"


def test_features_match_the_converters_dataset_features():
    from lerobot.configs.types import FeatureType
    from lerobot.envs.utils import env_to_policy_features

    cls = registered_env_config()
    cameras = {"top": (48, 64), "wrist": (32, 40)}
    dataset = convert.features_for(cameras, use_videos=True, environment_state=True)
    policy = env_to_policy_features(cls(cameras=cameras))
    # Every policy input/output of the env is a feature of the converter's datasets, same shape.
    for key, feature in policy.items():
        assert key in dataset, key
        expected = dataset[key]["shape"]
        if feature.type is FeatureType.VISUAL:
            expected = (3, *expected[:2])  # channel first, as LeRobot's policies see images
        assert tuple(feature.shape) == tuple(expected), key
    # ... and every camera and the state of the dataset is one of the env's.
    assert {k for k in dataset if k.startswith("observation.")} == set(policy) - {"action"}
    assert policy["action"].type is FeatureType.ACTION

    # The defaults are the converter's: the cube's pose included, unless left out on both sides.
    assert env_to_policy_features(cls())["observation.environment_state"].shape == (7,)
    state_only = env_to_policy_features(cls(environment_state=False))
    assert set(state_only) == {"observation.state", "action"}
    assert "observation.environment_state" not in convert.features_for({}, use_videos=True, environment_state=False)


def test_bad_task_or_camera_is_refused():
    cls = registered_env_config()
    with pytest.raises(ValueError, match="task"):
        cls(task="stack_cubes")
    with pytest.raises(ValueError, match="camera"):
        cls(cameras={"side": (48, 64)})


def test_the_adapter_converts_observations_and_actions_to_lerobot_units():
    from so101.lerobot.adapter import observation_from_sim, sim_action_from_lerobot

    low, high = units.JOINT_LIMITS.T
    joints = low + (high - low) * np.array([0.1, 0.3, 0.5, 0.7, 0.9, 0.25])
    velocities = np.arange(6) * 0.1
    cube = np.array([0.2, -0.1, 0.02, 1.0, 0.0, 0.0, 0.0])
    state = np.concatenate([joints, velocities, cube]).astype(np.float32)
    image = np.full((48, 64, 3), 7, dtype=np.uint8)

    from so101.envs import observation_from_state

    sim_observation = observation_from_state(state, {"top": image, "front": image})
    observation = observation_from_sim(sim_observation, {"top": (48, 64)}, True)
    assert set(observation) == {"agent_pos", "environment_state", "pixels"}
    assert observation["agent_pos"].dtype == np.float32
    # Degrees for the arm, 0-100 over the gripper's range (computed here, not with so101.units).
    assert np.allclose(observation["agent_pos"][:5], joints[:5] * 180 / np.pi, atol=1e-3)
    assert np.isclose(observation["agent_pos"][5], 25.0, atol=1e-3)
    assert np.allclose(observation["environment_state"], cube)
    assert list(observation["pixels"]) == ["top"] and observation["pixels"]["top"] is image

    bare = observation_from_sim(observation_from_state(state, None), {}, False)
    assert set(bare) == {"agent_pos"}

    # Actions: the inverse; the converter's dataset actions come back as the sim's radians.
    action = units.lerobot_from_radians(joints).astype(np.float32)
    assert np.allclose(sim_action_from_lerobot(action), joints, atol=1e-5)
    assert np.isclose(sim_action_from_lerobot([0, 0, 0, 0, 0, 100])[5], contract.JOINT_LIMITS[-1][1])
    assert np.isclose(sim_action_from_lerobot([0, 0, 0, 0, 0, 0])[5], contract.JOINT_LIMITS[-1][0])
    with pytest.raises(ValueError):
        sim_action_from_lerobot([0, 0, 0])
