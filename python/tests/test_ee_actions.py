"""End-effector actions (so101.ee, no DDS): the forward kinematics checked against MuJoCo's own
(the scene's gripper_tip site), the Gym envs acting on end-effector targets (reaching them, the
clamp reported, the same trajectory as the joint targets they stand for, the vector env's IK
starting over with each episode), the converter's --action-space ee read back by LeRobot, and the
robot type's end-effector command with LeRobot's max_relative_target."""

from __future__ import annotations

import io
from contextlib import redirect_stdout

import gymnasium as gym
import numpy as np
import pytest
from bag_writer import EpisodeBag

import so101  # noqa: F401 - registers the envs
from so101.ee import EE_FEATURE_NAMES, ee_limits, ee_poses, lerobot_ee_from_ee
from so101.envs.inprocess import default_scene
from so101.units import JOINT_LIMITS, JOINT_NAMES, lerobot_from_radians, radians_from_lerobot


def mujoco_grasp_points(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's own forward kinematics of the scene: the gripper_tip site's position in the base
    frame and its approach direction (the gripper frame's -z), per row of joints (rad)."""
    import mujoco
    import so101_native

    model = mujoco.MjModel.from_xml_string(so101_native.scene_xml(default_scene(), lite=True))
    data = mujoco.MjData(model)
    names = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
    addresses = [model.jnt_qposadr[model.joint(name).id] for name in names]
    site = model.site("gripper_tip").id
    positions, approaches = [], []
    for row in joints:
        data.qpos[addresses] = row
        mujoco.mj_kinematics(model, data)
        positions.append(data.site_xpos[site] - data.body("base").xpos)
        approaches.append(-data.site_xmat[site].reshape(3, 3)[:, 2])
    return np.array(positions), np.array(approaches)


def test_the_end_effector_pose_is_mujocos_grasp_point():
    rng = np.random.default_rng(1)
    joints = rng.uniform(JOINT_LIMITS[:, 0] * 0.7, JOINT_LIMITS[:, 1] * 0.7, size=(50, 6))
    poses = ee_poses(joints)
    positions, approaches = mujoco_grasp_points(joints)
    assert np.abs(poses[:, :3] - positions).max() < 1e-6
    # The pitch: the approach's angle below the horizontal, towards the arm's front.
    horizontal = np.hypot(approaches[:, 0], approaches[:, 1])
    forward = np.sign(approaches[:, 0] * np.cos(joints[:, 0]) - approaches[:, 1] * np.sin(joints[:, 0]))
    pitch = np.arctan2(-approaches[:, 2], forward * horizontal)
    assert np.abs(np.angle(np.exp(1j * (poses[:, 3] - pitch)))).max() < 1e-6
    assert np.array_equal(poses[:, 5], joints[:, 5])


def test_the_env_reaches_an_end_effector_target_and_reports_the_unreachable():
    from gymnasium.utils.env_checker import check_env

    from so101.envs import make_env

    check_env(make_env("cube_to_bin", action_space="ee"), skip_render_check=True)
    env = gym.make("so101/CubeToBin-v0", action_space="ee")
    observation, _ = env.reset(seed=4)
    assert env.action_space.shape == (6,) and observation["ee_state"].shape == (6,)
    target = observation["ee_state"] + np.array([0.03, 0.04, -0.05, 0.3, -0.4, 0.5])
    for _ in range(60):
        observation, _, _, _, info = env.step(target)
    assert not info["ee_clamped"] and info["ee_position_error"] < 1e-3
    reached = observation["ee_state"]
    assert np.abs(reached[:3] - target[:3]).max() < 0.004, reached - target
    assert np.abs(reached[3:5] - target[3:5]).max() < 0.03, reached - target

    far = target.copy()
    far[0] = 0.9  # twice the arm's reach
    observation, _, _, _, info = env.step(far)
    assert info["ee_clamped"] and info["ee_position_error"] > 0.3
    with pytest.raises(ValueError, match="six finite end-effector coordinates"):
        env.step(np.array([0.2, 0.0, np.nan, 0.0, 0.0, 0.0]))
    env.close()


def test_end_effector_targets_drive_the_arm_as_the_joint_targets_they_stand_for():
    joint_env = gym.make("so101/TouchCube-v0")
    ee_env = gym.make("so101/TouchCube-v0", action_space="ee")
    first, _ = joint_env.reset(seed=9)
    ee_env.reset(seed=9)
    start = first["agent_pos"]
    path = [start + (k / 40) * np.array([0.4, 0.3, -0.3, 0.5, -0.6, 0.8]) for k in range(1, 41)]
    for joints in path:
        by_joints, *_ = joint_env.step(joints)
        by_ee, *_ = ee_env.step(ee_poses(joints))
    assert np.abs(by_joints["agent_pos"] - by_ee["agent_pos"]).max() < 2e-3
    assert np.abs(by_joints["environment_state"] - by_ee["environment_state"]).max() < 1e-3


def test_the_vector_env_starts_its_ik_over_with_each_episode():
    envs = gym.make_vec("so101/CubeToBin-v0", num_envs=2, action_space="ee", max_episode_steps=3)
    observation, _ = envs.reset(seed=5)
    assert envs.single_action_space.shape == (6,) and observation["ee_state"].shape == (2, 6)
    target = observation["ee_state"].copy()
    target[:, 2] -= 0.05
    target[0, 4] = ee_limits()[4, 0] + 0.1  # world 0's wrist far round
    for _ in range(3):
        observation, _, _, truncated, info = envs.step(target)
    assert truncated.all() and not info["ee_clamped"].any()
    assert np.abs(envs.commander.in_force[0, 4] - JOINT_LIMITS[4, 1]) < 0.2  # where the IK stands now
    # The autoreset step (its actions ignored): each world's IK starts over from its new episode's
    # joints, not from the targets the last episode left.
    observation, *_ = envs.step(target)
    assert np.array_equal(envs.commander.in_force, observation["agent_pos"])
    new_start = observation["ee_state"].copy()
    observation, _, _, _, info = envs.step(new_start)
    assert not info["ee_clamped"].any()
    assert np.abs(observation["ee_state"][:, :3] - new_start[:, :3]).max() < 0.002
    envs.close()


def ee_bag(directory, joints: list[np.ndarray]):
    """An episode whose arm is commanded (and measured) through `joints`, one pose every 0.2 s."""
    bag = EpisodeBag(directory)
    for k in range(61):
        t = k / 30
        bag.joint_state(t, joints[min(k // 6, len(joints) - 1)] * 0.9)
        bag.cube(t)
    for k, pose in enumerate(joints):
        bag.array_command(0.01 + 0.2 * k, pose)
    bag.reward(0.0, 0.0)
    bag.success(0.0, True)
    return bag.close()


def test_the_converter_writes_end_effector_actions_and_state_lerobot_reads(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from so101.dataset.convert import main

    rng = np.random.default_rng(3)
    joints = [rng.uniform(JOINT_LIMITS[:, 0] * 0.6, JOINT_LIMITS[:, 1] * 0.6) for _ in range(10)]
    ee_bag(tmp_path / "bags" / "episode_000000", joints)
    datasets = {}
    for space in ("joint", "ee"):
        out = io.StringIO()
        with redirect_stdout(out):
            status = main([str(tmp_path / "bags"), "--output", str(tmp_path / space), "--quiet", "--action-space", space,
                           "--repo-id", f"local/{space}"])  # fmt: skip
        assert status == 0, out.getvalue()
        datasets[space] = (LeRobotDataset(f"local/{space}", root=tmp_path / space), out.getvalue())
    joint, _ = datasets["joint"]
    ee, summary = datasets["ee"]
    assert "end-effector actions: 0 of 61 (0.00 %) out of reach" in summary, summary
    assert ee.meta.features["action"]["names"] == EE_FEATURE_NAMES
    assert ee.meta.features["observation.ee_state"]["names"] == EE_FEATURE_NAMES
    assert "observation.ee_state" not in joint.meta.features

    def column(dataset, key):
        return np.stack([np.asarray(value) for value in dataset.hf_dataset[key]]).astype(np.float64)

    joint_action = radians_from_lerobot(column(joint, "action"))
    state = radians_from_lerobot(column(joint, "observation.state"))
    assert np.array_equal(column(ee, "observation.state"), column(joint, "observation.state"))
    for ee_key, joints_of in (("action", joint_action), ("observation.ee_state", state)):
        values = column(ee, ee_key)
        positions, _ = mujoco_grasp_points(joints_of)
        assert np.abs(values[:, :3] - positions).max() < 1e-5, ee_key  # float32 metres
        assert np.allclose(values[:, 5], lerobot_from_radians(joints_of)[:, 5], atol=1e-3), ee_key  # gripper 0-100
        assert np.allclose(values, lerobot_ee_from_ee(ee_poses(joints_of)), atol=1e-4), ee_key
    # The commanded poses are all there, as end-effector targets.
    assert len({tuple(np.round(row, 4)) for row in column(ee, "action")}) == len(joints)
    # so101-replay sends joint targets: it refuses end-effector ones instead of misreading them.
    from so101.stack.replay import actions_from_dataset

    with pytest.raises(SystemExit, match="end-effector targets"):
        actions_from_dataset(tmp_path / "ee", "local/ee", 0, "lerobot")
    assert actions_from_dataset(tmp_path / "joint", "local/joint", 0, "lerobot")[1].shape == (61, 6)


def test_a_policy_s_actions_are_known_from_its_training_dataset(tmp_path):
    import json

    from so101.evaluate.policy import PolicyError, detected_action_space

    def checkpoint(names, dataset_exists=True):
        root = tmp_path / f"dataset_{len(list(tmp_path.iterdir()))}"
        if dataset_exists:
            (root / "meta").mkdir(parents=True)
            (root / "meta" / "info.json").write_text(json.dumps({"features": {"action": {"names": names}}}))
        model = root.with_name(root.name + "_model")
        model.mkdir()
        (model / "train_config.json").write_text(json.dumps({"dataset": {"root": str(root)}}))
        return str(model)

    # Recorded by lerobot-record with the robot type's action_space=ee: no observation.ee_state.
    assert detected_action_space(checkpoint(EE_FEATURE_NAMES), reads_ee_state=False) == "ee"
    assert detected_action_space(checkpoint([f"{j}.pos" for j in JOINT_NAMES]), reads_ee_state=False) == "joint"
    # The dataset elsewhere (a Hub checkpoint): what the policy reads decides.
    assert detected_action_space(checkpoint(EE_FEATURE_NAMES, dataset_exists=False), reads_ee_state=True) == "ee"
    assert detected_action_space(str(tmp_path / "nowhere"), reads_ee_state=False) == "joint"
    with pytest.raises(PolicyError, match="neither joint nor end-effector"):
        detected_action_space(checkpoint(["a", "b"]), reads_ee_state=False)


def test_the_robot_type_turns_an_end_effector_action_into_a_capped_joint_command():
    from so101.lerobot.robot.actions import command_from_ee_action

    hold = np.array([0.1, -0.3, 0.5, 1.0, 0.0, 0.5])
    start = lerobot_ee_from_ee(ee_poses(hold))
    # A partial action: z 2 cm lower, every other coordinate held.
    command = command_from_ee_action({"ee.z": start[2] - 0.02}, hold, hold)
    assert not command.clamped and list(command.sent) == EE_FEATURE_NAMES
    reached = lerobot_ee_from_ee(ee_poses(command.radians))
    assert reached[2] == pytest.approx(start[2] - 0.02, abs=1e-4)
    assert np.abs(np.delete(reached - start, 2)).max() < 1e-3
    # LeRobot's max_relative_target caps each joint's step, as for a joint action.
    capped = command_from_ee_action({"ee.z": start[2] - 0.15}, hold, hold, max_relative_target=2.0)
    assert np.abs(lerobot_from_radians(capped.radians) - lerobot_from_radians(hold)).max() <= 2.0 + 1e-9
    assert capped.sent["ee.z"] == pytest.approx(lerobot_ee_from_ee(ee_poses(capped.radians))[2])
    # The capped step is not the new target: the next partial action keeps the target asked for
    # (x where it was), while the arm goes on towards it.
    following = command_from_ee_action({"ee.gripper": 10.0}, capped.radians, capped.radians, 2.0, capped.target)
    assert following.target[0] == pytest.approx(start[0]) and following.target[2] == pytest.approx(start[2] - 0.15)
    assert following.sent["ee.z"] < capped.sent["ee.z"]
    # Out of reach: the nearest reachable pose, inside the limits, and said so.
    far = command_from_ee_action({"ee.x": 2.0}, hold, hold)
    assert far.clamped and np.all((far.radians >= JOINT_LIMITS[:, 0]) & (far.radians <= JOINT_LIMITS[:, 1]))
    with pytest.raises(ValueError, match="ee.y"):
        command_from_ee_action({"ee.y": float("nan")}, hold, hold)
    # Keys that are not its own (a joint action, LeRobot's ee.wx) are refused, not held.
    for stranger in ({"shoulder_pan.pos": 10.0}, {"ee.x": start[0], "ee.wx": 0.1}):
        with pytest.raises(ValueError, match="not end-effector ones"):
            command_from_ee_action(stranger, hold, hold)
