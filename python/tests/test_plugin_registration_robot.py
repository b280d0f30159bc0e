"""The robot plugin without ROS: LeRobot's own plugin discovery makes `so101_ros` a robot type, the
config parses from CLI-style arguments, features are known before connect, and the action logic
(LeRobot units -> radians, holding, clamping, clipping) is right."""

from __future__ import annotations

import math
from dataclasses import dataclass

import draccus
import numpy as np
import pytest
import torch
from lerobot.robots import RobotConfig

from so101.units import FEATURE_NAMES, JOINT_LIMITS, lerobot_from_radians


@dataclass
class Cli:  # as lerobot-record's RecordConfig holds its robot
    robot: RobotConfig


@pytest.fixture(scope="module")
def registered():
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    return RobotConfig


def test_so101_ros_is_a_known_robot_type_that_parses_from_cli_arguments(registered, tmp_path, monkeypatch):
    assert "so101_ros" in registered.get_known_choices()
    config = draccus.parse(
        Cli,
        args=[
            "--robot.type=so101_ros",
            "--robot.namespace=arm",
            "--robot.joint_commands_topic=/other/commands",
            "--robot.cameras={top: {width: 64, height: 48, fps: 30}, wrist: {topic: /cam/w, width: 32, height: 24, fps: 15}}",
            "--robot.max_relative_target=5",
        ],
    ).robot
    from so101.lerobot.robot import SO101ROS, SO101ROSConfig

    assert isinstance(config, SO101ROSConfig) and config.type == "so101_ros"
    assert config.namespace == "arm" and config.joint_states_topic == "joint_states"
    assert config.joint_commands_topic == "/other/commands" and config.max_relative_target == 5
    assert config.cameras["top"].topic == "camera/top/image_raw" and config.cameras["wrist"].topic == "/cam/w"

    # LeRobot's own factory builds the robot (no ROS until connect); features before connect.
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path))
    from lerobot.robots.utils import make_robot_from_config

    config.calibration_dir = tmp_path
    robot = make_robot_from_config(config)
    assert isinstance(robot, SO101ROS) and not robot.is_connected and robot.is_calibrated
    assert list(robot.action_features) == FEATURE_NAMES
    assert all(t is float for t in robot.action_features.values())
    assert robot.observation_features == {**{k: float for k in FEATURE_NAMES}, "top": (48, 64, 3), "wrist": (24, 32, 3)}
    assert len(robot.cameras) == 2
    robot.disconnect()  # tolerated while not connected


def test_actions_in_lerobot_units_become_radians_and_missing_joints_hold():
    from so101.lerobot.robot import command_from_action

    hold = np.array([0.1, -0.2, 0.3, -0.4, 0.5, 0.6])
    action = {
        "shoulder_pan.pos": torch.tensor(45.0),  # 0-d tensor, as lerobot-replay sends
        "elbow_flex.pos": np.float32(-30.0),
        "gripper.pos": 100.0,
        "wrist_roll.pos": None,
        "unknown.pos": 3.0,
    }
    radians, sent = command_from_action(action, hold)
    assert radians[0] == pytest.approx(math.radians(45))
    assert radians[2] == pytest.approx(math.radians(-30))
    assert radians[5] == pytest.approx(JOINT_LIMITS[5, 1])  # gripper 100 = open limit
    assert radians[[1, 3, 4]] == pytest.approx(hold[[1, 3, 4]])
    assert list(sent) == FEATURE_NAMES and sent["shoulder_pan.pos"] == pytest.approx(45.0)
    assert sent["wrist_flex.pos"] == pytest.approx(math.degrees(-0.4))
    # Nothing asked: hold everything.
    radians, sent = command_from_action({}, hold)
    assert radians == pytest.approx(hold)
    assert list(sent.values()) == pytest.approx(list(lerobot_from_radians(hold)))


def test_actions_are_clipped_to_the_joint_limits_and_clamped_to_max_relative_target():
    from so101.lerobot.robot import command_from_action

    zero = np.zeros(6)
    radians, sent = command_from_action({"shoulder_pan.pos": 500.0, "gripper.pos": -50.0}, zero)
    assert radians[0] == pytest.approx(JOINT_LIMITS[0, 1]) and radians[5] == pytest.approx(JOINT_LIMITS[5, 0])
    assert sent["shoulder_pan.pos"] == pytest.approx(math.degrees(JOINT_LIMITS[0, 1])) and sent["gripper.pos"] == pytest.approx(0)
    # Each joint moves at most 5 units from the present position.
    present = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    radians, sent = command_from_action({"shoulder_pan.pos": 40.0, "elbow_flex.pos": -2.0}, zero, present, 5.0)
    assert sent["shoulder_pan.pos"] == pytest.approx(5.0) and sent["elbow_flex.pos"] == pytest.approx(-2.0)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), "up", [1.0, 2.0]])
def test_an_action_that_is_not_a_finite_number_is_refused_naming_the_joint(bad):
    from so101.lerobot.robot import command_from_action

    with pytest.raises(ValueError, match="elbow_flex.pos"):
        command_from_action({"shoulder_pan.pos": 10.0, "elbow_flex.pos": bad}, np.zeros(6))
