"""The Gymnasium environments' ROS backend (so101_sim_node in lockstep, --step-on-command, driven
through rclpy): gymnasium's own env checker, cameras, and parity with the in-process backend (the
same seed and actions give the same trajectory over ROS as in-process, to 1e-9, over 600 steps),
joint or end-effector actions."""

from __future__ import annotations

import numpy as np
from harness import blind_domain


def state_of(observation) -> np.ndarray:
    return np.concatenate([observation["agent_pos"], observation["agent_vel"], observation["environment_state"]])


def assert_a_step_alike(ros, local, action) -> None:
    """One step of both backends with `action`: the same state, to 1e-9."""
    ros_observation, *_ = ros.step(action)
    local_observation, *_ = local.step(action)
    assert np.abs(state_of(ros_observation) - state_of(local_observation)).max() <= 1e-9


def test_the_ros_backend_passes_the_checker_and_follows_the_in_process_trajectory():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    ros = gym.make("so101:so101/CubeToBin-v0", backend="ros")
    local = gym.make("so101/CubeToBin-v0")
    try:
        check_env(ros.unwrapped, skip_render_check=True)
        # An action sequence that moves every joint, reaches limits (clamped) and rests.
        rng = np.random.default_rng(4)
        waypoints = rng.uniform(ros.unwrapped.action_space.low, ros.unwrapped.action_space.high, size=(12, 6)) * 1.2
        actions = np.repeat(waypoints, 50, axis=0).astype(np.float32)
        ros_observation, _ = ros.reset(seed=11)
        local_observation, _ = local.reset(seed=11)
        worst = np.abs(state_of(ros_observation) - state_of(local_observation)).max()
        positions = []
        for step, action in enumerate(actions):
            ros_observation, ros_reward, ros_terminated, _, ros_info = ros.step(action)
            local_observation, local_reward, local_terminated, _, local_info = local.step(action)
            difference = np.abs(state_of(ros_observation) - state_of(local_observation)).max()
            worst = max(worst, difference)
            positions.append(ros_observation["agent_pos"])
            assert difference <= 1e-9, f"step {step}: the backends differ by {difference}"
            assert ros_reward == local_reward and ros_info["is_success"] == local_info["is_success"]
            if ros_terminated or local_terminated:
                break
        assert step == len(actions) - 1, "an episode of random motion should not succeed"
        # The arm really moved: every joint swept a wide range on the way.
        swept = np.ptp(positions, axis=0)
        assert swept.min() > 0.3, swept
        print(f"600 steps, largest difference between the backends {worst:.3g}")
    finally:
        ros.close()
        local.close()


def test_a_lost_reply_to_the_first_reset_restarts_the_node_with_the_same_seed():
    """A node just started can run /sim/reset and lose the reply (its reply writer not yet matched
    to the client): the env restarts the node with the same seed instead of failing the run."""
    import gymnasium as gym

    ros = gym.make("so101:so101/CubeToBin-v0", backend="ros")
    local = gym.make("so101/CubeToBin-v0")
    env = ros.unwrapped
    real_call, dropped = env._call, []

    def call_losing_the_first_reply(client, what, timeout=None):
        if not dropped:
            dropped.append(what)
            client.call_async(env._trigger())  # the node resets; this reply is never awaited
            raise TimeoutError(f"no {what} (the reply dropped by the test)")
        return real_call(client, what, timeout)

    env._call = call_losing_the_first_reply
    try:
        ros_observation, _ = ros.reset(seed=5)
        local_observation, _ = local.reset(seed=5)
        assert dropped == ["/sim/reset"]
        assert np.abs(state_of(ros_observation) - state_of(local_observation)).max() <= 1e-9
        assert_a_step_alike(ros, local, local_observation["agent_pos"])
    finally:
        ros.close()
        local.close()


def test_a_participant_blind_to_the_node_is_replaced(monkeypatch, caplog):
    """Fast DDS can miss a starting node's publications for good (so101.stack.discovery): the env
    then replaces its participant. The blindness is made here: the env's first participant opens
    in another ROS domain than the node it starts."""
    import os

    import gymnasium as gym

    node_domain = os.environ.get("ROS_DOMAIN_ID", "0")
    monkeypatch.setenv("ROS_DOMAIN_ID", blind_domain())
    ros = gym.make("so101:so101/CubeToBin-v0", backend="ros")
    local = gym.make("so101/CubeToBin-v0")
    monkeypatch.setenv("ROS_DOMAIN_ID", node_domain)
    try:
        ros_observation, _ = ros.reset(seed=3)
        local_observation, _ = local.reset(seed=3)
        assert "starting a fresh DDS participant" in caplog.text
        assert_a_step_alike(ros, local, local_observation["agent_pos"])
    finally:
        ros.close()
        local.close()


def test_with_cameras_each_step_brings_the_frames_of_its_state():
    import gymnasium as gym

    env = gym.make("so101:so101/TouchCube-v0", backend="ros", cameras={"top": (48, 64), "front": (60, 80)})
    try:
        observation, _ = env.reset(seed=2)
        assert env.observation_space.contains(observation)
        first = observation["pixels"]["front"].astype(np.int16)
        assert observation["pixels"]["top"].shape == (48, 64, 3) and first.shape == (60, 80, 3)
        target = np.array([0.8, -0.6, 0.5, 0.8, 0.0, 1.2], dtype=np.float32)
        for _ in range(45):
            observation, *_ = env.step(target)
        assert env.observation_space.contains(observation)
        assert np.abs(observation["agent_pos"] - target).max() < 0.05
        # The arm moved in view: the front camera's frame changed.
        changed = np.abs(observation["pixels"]["front"].astype(np.int16) - first).max(axis=2) > 30
        assert changed.mean() > 0.01, f"only {changed.mean():.3%} of the front view changed"
    finally:
        env.close()


def test_end_effector_actions_drive_both_backends_alike():
    """action_space="ee" on so101_sim_node in lockstep: the same end-effector targets give the
    in-process trajectory, the clamp reported alike."""
    import gymnasium as gym

    ros = gym.make("so101:so101/CubeToBin-v0", backend="ros", action_space="ee")
    local = gym.make("so101/CubeToBin-v0", action_space="ee")
    try:
        ros_observation, _ = ros.reset(seed=12)
        local_observation, _ = local.reset(seed=12)
        start = local_observation["ee_state"]
        # Down towards the table and round, then a target out of reach.
        targets = [start + (k / 30) * np.array([-0.1, 0.08, -0.12, 0.9, 0.5, 0.6]) for k in range(1, 31)]
        targets.append(targets[-1] + np.array([0.6, 0.0, 0.0, 0.0, 0.0, 0.0]))
        for step, target in enumerate(targets):
            ros_observation, _, _, _, ros_info = ros.step(target)
            local_observation, _, _, _, local_info = local.step(target)
            difference = np.abs(state_of(ros_observation) - state_of(local_observation)).max()
            assert difference <= 1e-9, f"step {step}: the backends differ by {difference}"
            assert ros_info["ee_clamped"] == local_info["ee_clamped"]
            assert np.array_equal(ros_observation["ee_state"], local_observation["ee_state"])
        assert local_info["ee_clamped"] and ros_info["ee_clamped"]
        assert np.abs(local_observation["ee_state"][:3] - start[:3]).max() > 0.1  # it moved
    finally:
        ros.close()
        local.close()
