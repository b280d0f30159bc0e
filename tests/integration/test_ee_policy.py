"""A policy that acts in end-effector space, through the whole stack: expert demonstrations recorded
in-process with end-effector actions (so101-learn demos --action-space ee) are the joint
demonstrations of the same seed seen through the forward kinematics, read by LeRobot; a tiny ACT
trained on them by lerobot-train runs through so101-run-policy (an evaluation on so101_sim_node in
lockstep, the end-effector actions recognised from the policy's inputs), through lerobot-eval on the
env type with --env.action_space=ee, and live on the driver (servo emulator) with so101_camera_node,
its commands inside the limits; the robot type so101_ros with action_space=ee moves the driver's
arm to an end-effector target, LeRobot's max_relative_target capping each step."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from harness import TINY_ACT, SimNode, best_effort_qos, node_binary, reliable_qos, wait_until

from so101 import contract
from so101.ee import EE_FEATURE_NAMES, ee_poses, lerobot_ee_from_ee
from so101.units import JOINT_LIMITS, radians_from_lerobot

VENV_BIN = Path(sys.executable).parent
JOINTS = list(contract.JOINT_NAMES)
CAMERA = "top:64x48"


def run(argv: list, timeout: float, tmp: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    if tmp is not None:
        env.update(HF_HOME=str(tmp / "hf"), HF_LEROBOT_HOME=str(tmp / "lerobot"))
    return subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=timeout, env=env)


def column(dataset, key: str) -> np.ndarray:
    return np.stack([np.asarray(value) for value in dataset.hf_dataset[key]]).astype(np.float64)


@pytest.fixture(scope="module")
def demonstrations(tmp_path_factory) -> dict[str, Path]:
    """Two expert demonstrations of seed 4 (one 64x48 camera, no cube pose), as joint and as
    end-effector datasets."""
    tmp = tmp_path_factory.mktemp("ee_demos")
    roots = {}
    for space in ("joint", "ee"):
        done = run(
            [VENV_BIN / "so101-learn", "demos", "--backend", "inprocess", "--episodes", "2", "--seed", "4",
             "--cameras", CAMERA, "--lite", "--no-environment-state", "--action-space", space,
             "--repo-id", f"local/ee_{space}", "--output", tmp / space],
            300,
        )  # fmt: skip
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        roots[space] = tmp / space / "dataset"
    return roots


def test_end_effector_demonstrations_are_the_joint_ones_through_the_kinematics(demonstrations):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    joint = LeRobotDataset("local/ee_joint", root=demonstrations["joint"])
    ee = LeRobotDataset("local/ee_ee", root=demonstrations["ee"])
    assert ee.meta.features["action"]["names"] == EE_FEATURE_NAMES
    assert ee.meta.features["observation.ee_state"]["shape"] == (6,)
    assert ee.num_frames == joint.num_frames and ee.num_episodes == 2
    assert np.array_equal(column(ee, "observation.state"), column(joint, "observation.state"))
    expected = lerobot_ee_from_ee(ee_poses(radians_from_lerobot(column(joint, "action"))))
    assert np.abs(column(ee, "action") - expected).max() < 1e-4
    expected_state = lerobot_ee_from_ee(ee_poses(radians_from_lerobot(column(joint, "observation.state"))))
    assert np.abs(column(ee, "observation.ee_state") - expected_state).max() < 1e-4
    # The video frames LeRobot decodes are the same demonstrations'.
    assert np.abs(ee[100]["observation.images.top"].numpy() - joint[100]["observation.images.top"].numpy()).max() < 0.05


@pytest.fixture(scope="module")
def ee_policy(demonstrations, tmp_path_factory) -> Path:
    output = tmp_path_factory.mktemp("ee_act") / "train"
    done = run(
        [VENV_BIN / "lerobot-train", "--dataset.repo_id=local/ee_ee", f"--dataset.root={demonstrations['ee']}", *TINY_ACT,
         "--policy.n_vae_encoder_layers=1", "--policy.chunk_size=10", "--policy.n_action_steps=10", "--steps=3",
         "--batch_size=4", "--num_workers=0", "--save_freq=3", "--log_freq=1", "--wandb.enable=false",
         f"--output_dir={output}"],
        300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return output / "checkpoints" / "last" / "pretrained_model"


def test_an_end_effector_policy_runs_on_the_sim_node_and_in_lerobot_eval(ee_policy, tmp_path):
    evaluation = tmp_path / "eval"
    done = run(
        [VENV_BIN / "so101-run-policy", ee_policy, "--eval", "1", "--seed", "21", "--episode-time", "1", "--lite",
         "--videos", "0", "--output", evaluation, "--quiet"],
        300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "(act, ee actions)" in done.stderr, done.stderr[-3000:]
    assert re.search(r"\d+ of 30 end-effector targets out of reach", done.stderr), done.stderr[-3000:]
    episode = json.loads((evaluation / "eval_info.json").read_text())["per_episode"][0]
    assert episode["steps"] == 30 and episode["success"] is False, episode

    done = run(
        [VENV_BIN / "lerobot-eval", f"--policy.path={ee_policy}", "--policy.device=cpu", "--env.type=so101_sim",
         "--env.cameras={top: [48, 64]}", "--env.action_space=ee", "--env.episode_length=8", "--eval.n_episodes=1",
         "--eval.batch_size=1", "--eval.use_async_envs=false", "--seed=7", f"--output_dir={tmp_path / 'lerobot_eval'}"],
        300,
        tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    overall = json.loads((tmp_path / "lerobot_eval" / "eval_info.json").read_text())["overall"]
    assert overall["n_episodes"] == 1 and overall["pc_success"] == 0.0, overall


def test_an_end_effector_policy_drives_the_arm_s_driver(ee_policy, arm_factory, ros, tmp_path):
    from sensor_msgs.msg import JointState

    arm, _emulator = arm_factory()
    cameras = SimNode(node_binary("so101_camera_node"), ["--camera", "top=fake:64x48@30"], tmp_path / "camera_node.log")
    states = ros.subscribe("/joint_states", JointState, best_effort_qos())
    commands = ros.subscribe("/joint_commands", JointState, reliable_qos(1000))
    first = states.next_message(20.0, arm)
    before = np.array([dict(zip(first.name, first.position))[j] for j in JOINTS])
    done = run([VENV_BIN / "so101-run-policy", ee_policy, "--duration", "3", "--compressed"], 120)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "end-effector targets out of reach" in done.stdout, done.stdout
    arm.assert_alive()
    assert cameras.stop() == 0, cameras.log_tail()
    received = commands.messages()
    assert received, "no command reached the driver"
    positions = np.array([msg.position for msg in received])
    assert np.all(np.isfinite(positions))
    assert np.all(positions >= JOINT_LIMITS[:, 0] - 1e-9) and np.all(positions <= JOINT_LIMITS[:, 1] + 1e-9)
    after = np.array([dict(zip(states.latest().name, states.latest().position))[j] for j in JOINTS])
    assert np.abs(after - before).max() > 0.05, f"the driven arm did not move: {before} -> {after}"


def test_the_robot_type_moves_the_driver_to_an_end_effector_target(arm_factory, tmp_path):
    from so101.lerobot.robot import SO101ROS, SO101ROSConfig

    node, _emulator = arm_factory()
    robot = SO101ROS(
        SO101ROSConfig(
            id="arm", calibration_dir=tmp_path / "cal", connect_timeout_s=30.0, action_space="ee", max_relative_target=3.0
        )
    )
    robot.connect()
    try:
        assert list(robot.action_features) == EE_FEATURE_NAMES
        observation = robot.get_observation()
        present = radians_from_lerobot(np.array([observation[f"{j}.pos"] for j in JOINTS]))
        start = lerobot_ee_from_ee(ee_poses(present))
        # 8 cm nearer and 4 cm lower, the jaws half open; y, pitch and roll as they are.
        target = {"ee.x": start[0] - 0.08, "ee.z": start[2] - 0.04, "ee.gripper": 40.0}
        steps = []

        def reached() -> bool:
            sent = robot.send_action(target)  # the driver's watchdog wants a stream
            steps.append(sent)
            joints = radians_from_lerobot(np.array([robot.get_observation()[f"{j}.pos"] for j in JOINTS]))
            now = lerobot_ee_from_ee(ee_poses(joints))
            return abs(now[0] - target["ee.x"]) < 0.004 and abs(now[2] - target["ee.z"]) < 0.004 and abs(now[5] - 40.0) < 2.0

        wait_until(reached, 15.0, "the driver's arm at the end-effector target", node)
        assert set(steps[0]) == set(EE_FEATURE_NAMES)
        # Capped at 3 LeRobot units per joint from where the arm stood: the first command went
        # only part of the way.
        assert target["ee.x"] + 0.001 < steps[0]["ee.x"] < start[0], (start, steps[0])
        # The coordinates the action did not name were held: the commanded pose kept them.
        for key in ("ee.y", "ee.pitch", "ee.roll"):
            assert steps[-1][key] == pytest.approx(start[EE_FEATURE_NAMES.index(key)], abs=1e-3), key
        with pytest.raises(ValueError, match="ee.x"):
            robot.send_action({"ee.x": float("inf")})
    finally:
        robot.disconnect()
