"""The Gymnasium environment over the sim in lockstep: gymnasium's own env checker, and an episode
whose observations, rewards and timing follow the sim."""

from __future__ import annotations

import numpy as np


def test_the_gymnasium_env_passes_the_checker_and_steps_the_sim():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    env = gym.make("so101:so101/CubeToBin-v0")
    try:
        check_env(env.unwrapped, skip_render_check=True)
        observation, _ = env.reset(seed=3)
        again, _ = env.reset(seed=3)
        assert np.array_equal(observation, again), "the same seed gave another first observation"
        assert observation.shape == (19,) and observation.dtype == np.float32
        cube = observation[12:15]
        assert 0.17 <= cube[0] <= 0.29 and -0.09 <= cube[1] <= 0.09 and abs(cube[2] - 0.765) < 0.005, cube
        # Holding a pose for 30 steps (1 s at 30 Hz): the arm gets there and stays, the cube rests.
        target = np.array([0.3, -0.2, 0.2, 0.5, 0.0, 0.5], dtype=np.float32)
        for _ in range(30):
            observation, reward, terminated, truncated, info = env.step(target)
        assert np.abs(observation[:6] - target).max() < 0.05, observation[:6]
        assert np.isfinite(reward) and not terminated and not truncated and info["success"] is False
        # Every command reached the sim before its step (the answer's count says so), or was counted.
        assert info["command_late"] in (False, True) and env.unwrapped.late_commands < 30
        assert np.linalg.norm(observation[12:15] - cube) < 1e-3, "the cube moved without being touched"
    finally:
        env.close()


def test_with_cameras_each_step_brings_the_frames_of_its_state():
    import gymnasium as gym

    env = gym.make("so101:so101/TouchCube-v0", cameras={"top": (48, 64), "front": (60, 80)})
    try:
        observation, _ = env.reset(seed=2)
        assert env.observation_space.contains(observation)
        first = observation["pixels"]["front"].astype(np.int16)
        assert observation["pixels"]["top"].shape == (48, 64, 3) and first.shape == (60, 80, 3)
        target = np.array([0.8, -0.6, 0.5, 0.8, 0.0, 1.2], dtype=np.float32)
        for _ in range(45):
            observation, *_ = env.step(target)
        assert env.observation_space.contains(observation)
        assert np.abs(observation["state"][:6] - target).max() < 0.05
        # The arm moved in view: the front camera's frame changed.
        changed = np.abs(observation["pixels"]["front"].astype(np.int16) - first).max(axis=2) > 30
        assert changed.mean() > 0.01, f"only {changed.mean():.3%} of the front view changed"
    finally:
        env.close()
