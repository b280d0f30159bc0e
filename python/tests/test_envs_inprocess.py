"""The in-process Gymnasium environments (so101.envs.inprocess over the so101_native extension): gymnasium's
checker, seeded resets, the native batch behind make_vec against single worlds, cameras, rewards,
and the scripted expert putting the cube in the bin. No ROS, no DDS."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import so101  # noqa: F401  (registers the environments)
from so101.envs import So101InProcessEnv, So101VectorEnv
from so101.evaluate.expert import ExpertPolicy

HOLD = np.array([0.3, -0.2, 0.2, 0.5, 0.0, 0.5], dtype=np.float32)


def rollout(env, seed: int, actions) -> list[np.ndarray]:
    observation, _ = env.reset(seed=seed)
    states = [np.concatenate([observation["agent_pos"], observation["agent_vel"], observation["environment_state"]])]
    for action in actions:
        observation, *_ = env.step(action)
        states.append(np.concatenate([observation["agent_pos"], observation["agent_vel"], observation["environment_state"]]))
    return states


def test_the_env_passes_gymnasiums_checker_and_seeds_reproduce_episodes():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("so101/CubeToBin-v0")
    assert isinstance(env.unwrapped, So101InProcessEnv)
    check_env(env.unwrapped, skip_render_check=True)
    env.action_space.seed(0)
    actions = [env.action_space.sample() * 0.3 for _ in range(40)]
    first = rollout(env, 7, actions)
    rollout(env, 3, actions[:5])  # another episode in between changes nothing
    again = rollout(env, 7, actions)
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    other = rollout(env, 8, actions)
    assert not np.array_equal(first[0][12:15], other[0][12:15]), "another seed, another cube placement"
    env.close()


def test_a_reset_starts_from_the_settled_pose_in_the_spawn_area():
    env = gym.make("so101/CubeToBin-v0")
    observation, info = env.reset(seed=3)
    # The arm sagged under gravity while settling: not the model's exact zero, but close to it.
    assert 0.002 < observation["agent_pos"][1] < 0.03, observation["agent_pos"]
    assert np.abs(observation["agent_vel"]).max() < 0.05
    x, y, z = observation["environment_state"][:3]
    assert 0.18 <= x <= 0.28 and -0.08 <= y <= 0.08 and abs(z - 0.765) < 0.005
    assert info["is_success"] is False and env.unwrapped.world.time == pytest.approx(0.3)
    for _ in range(30):
        observation, reward, terminated, truncated, info = env.step(HOLD)
    assert np.abs(observation["agent_pos"] - HOLD).max() < 0.05
    assert reward == 0.0 and not terminated and not truncated
    env.close()


def test_make_vec_is_the_native_batch_and_matches_single_worlds():
    vector = gym.make_vec("so101/TouchCube-v0", num_envs=3)
    assert isinstance(vector, So101VectorEnv)
    single = gym.make("so101/TouchCube-v0")
    rng = np.random.default_rng(1)
    actions = [rng.uniform(-0.5, 0.5, size=(3, 6)) for _ in range(25)]
    observation, _ = vector.reset(seed=10)
    batch_states = [observation["agent_pos"].copy()]
    for action in actions:
        observation, rewards, terminated, truncated, info = vector.step(action)
        batch_states.append(observation["agent_pos"].copy())
        assert rewards.shape == (3,) and info["is_success"].shape == (3,)
    for world in range(3):
        states = rollout(single, 10 + world, [action[world] for action in actions])
        for step, state in enumerate(states):
            assert np.array_equal(batch_states[step][world], state[:6]), (world, step)
    vector.close()
    single.close()


def test_the_batch_resets_a_finished_world_on_the_next_step():
    vector = So101VectorEnv(2, task="touch_cube", max_episode_steps=3)
    vector.reset(seed=0)
    hold = np.zeros((2, 6))
    for _ in range(3):
        observation, rewards, terminated, truncated, _ = vector.step(hold)
    assert truncated.all() and not terminated.any()
    observation, rewards, terminated, truncated, _ = vector.step(np.full((2, 6), 0.5))
    # The next step is the new episode's start: the action was ignored, the arm settled at home.
    assert np.abs(observation["agent_pos"]).max() < 0.03 and (rewards == 0).all()
    assert not truncated.any() and not terminated.any()
    vector.close()


def test_rewards_follow_the_task_and_the_dense_flag():
    touch = gym.make("so101/TouchCube-v0")
    observation, _ = touch.reset(seed=1)
    _, reward, *_ = touch.step(observation["agent_pos"].astype(np.float32))
    assert -0.5 < reward < -0.05, "touch_cube's reward is minus the tip-to-cube distance"
    sparse = gym.make("so101/TouchCubeSparse-v0")
    sparse.reset(seed=1)
    assert sparse.step(HOLD)[1] == 0.0
    dense = gym.make("so101/CubeToBin-v0", dense_reward=True)
    dense.reset(seed=1)
    assert 0.0 < dense.step(HOLD)[1] < 0.2, "the approach stage of the shaping"
    for env in (touch, sparse, dense):
        env.close()


def test_bad_actions_are_refused():
    env = gym.make("so101/CubeToBin-v0")
    env.reset(seed=0)
    for bad in (np.full(6, np.nan), np.zeros(5)):
        with pytest.raises(ValueError):
            env.step(bad)
    env.close()


def test_cameras_render_the_state_of_each_step():
    env = gym.make(
        "so101/CubeToBin-v0",
        cameras={"top": (48, 64), "wrist": (30, 40)},
        render_mode="rgb_array",
        render_camera="front",
        render_size=(24, 32),
    )
    observation, _ = env.reset(seed=2)
    assert observation["pixels"]["top"].shape == (48, 64, 3) and observation["pixels"]["wrist"].shape == (30, 40, 3)
    before = observation["pixels"]["wrist"].copy()
    for _ in range(15):
        observation, *_ = env.step(HOLD)
    assert observation["pixels"]["top"].std() > 5, "a blank frame"
    assert np.abs(observation["pixels"]["wrist"].astype(int) - before).mean() > 2, "the wrist camera moved with the arm"
    assert env.render().shape == (24, 32, 3)
    env.close()


def test_the_expert_puts_the_cube_in_the_bin():
    env = gym.make("so101/CubeToBin-v0")
    for seed in (0, 5):
        observation, _ = env.reset(seed=seed)
        expert = ExpertPolicy(waypoint_noise=0.003, action_noise=0.005, seed=seed)
        expert.reset(observation)
        for _ in range(400):
            observation, reward, terminated, truncated, info = env.step(expert(observation))
            if terminated:
                break
        assert terminated and info["is_success"] and reward == 1.0, seed
    env.close()


def test_the_expert_lifts_the_cube_and_holds_it():
    """lift_cube: the same planner grasps, lifts and holds; success needs both jaws on the cube
    5 cm up, so the cube_to_bin expert scores it while it carries the cube and not once it has
    let go over the bin."""
    env = gym.make("so101/LiftCube-v0", dense_reward=True)
    for seed in (1, 6):
        rewards = []
        observation, _ = env.reset(seed=seed)
        rest = observation["environment_state"][2]
        expert = ExpertPolicy(waypoint_noise=0.003, action_noise=0.005, seed=seed, task="lift_cube")
        expert.reset(observation)
        for _ in range(300):
            observation, reward, terminated, truncated, info = env.step(expert(observation))
            rewards.append(reward)
            if terminated:
                break
        assert terminated and info["is_success"] and reward == 1.0, seed
        assert observation["environment_state"][2] > rest + 0.05
        assert 0.0 < max(rewards[:-1]) < 1.0  # the dense shaping before success
    observation, _ = env.reset(seed=1)
    expert = ExpertPolicy(seed=1)  # cube_to_bin's plan
    expert.reset(observation)
    successes = []
    for _ in range(300):
        observation, _, _, _, info = env.step(expert(observation))
        successes.append(info["is_success"])
    carried = successes.index(True)
    assert not successes[-1] and False in successes[carried:]  # held while carried, then let go
    env.close()


def test_the_expert_places_the_cube_on_the_pad():
    env = gym.make("so101/PlaceCube-v0", dense_reward=True)
    for seed in (2, 7):
        observation, _ = env.reset(seed=seed)
        expert = ExpertPolicy(waypoint_noise=0.003, action_noise=0.005, seed=seed, task="place_cube")
        expert.reset(observation)
        held_high = False
        for _ in range(600):
            observation, reward, terminated, truncated, info = env.step(expert(observation))
            held_high |= observation["environment_state"][2] > 0.8  # carried, 3 cm and more above the table
            if terminated:
                break
        assert terminated and info["is_success"] and reward == 1.0 and held_high, seed
        # Resting on the table, left of the arm (the pad at y = 0.18 m).
        assert abs(observation["environment_state"][1] - 0.18) < 0.025
        assert observation["environment_state"][2] < 0.77
    env.close()


def test_the_expert_pushes_the_cube_onto_the_target():
    """push_cube: the jaws nearly closed push the cube along the table, never lift it, and it
    ends resting inside the round target (3 cm radius at x 0.26, y 0.13 m)."""
    env = gym.make("so101/PushCube-v0", dense_reward=True)
    for seed in (2, 7):
        observation, _ = env.reset(seed=seed)
        rest = observation["environment_state"][2]
        expert = ExpertPolicy(waypoint_noise=0.003, action_noise=0.005, seed=seed, task="push_cube")
        expert.reset(observation)
        rewards, highest = [], rest
        for _ in range(600):
            observation, reward, terminated, truncated, info = env.step(expert(observation))
            rewards.append(reward)
            highest = max(highest, observation["environment_state"][2])
            if terminated:
                break
        assert terminated and info["is_success"] and reward == 1.0, seed
        x, y, z = observation["environment_state"][:3]
        assert np.hypot(x - 0.26, y - 0.13) < 0.03 and abs(z - rest) < 0.003
        assert highest < rest + 0.01  # slid, not carried
        assert rewards[-2] > rewards[0]  # the dense reward grew as the cube neared the target
    env.close()


def test_the_expert_stacks_the_red_cube_on_the_green_one():
    """stack_cube: the second cube stands left of the arm (only in this task's scene); the red
    one ends resting on top of it, one edge higher than it lay."""
    env = gym.make("so101/StackCube-v0")
    for seed in (2, 7):
        observation, _ = env.reset(seed=seed)
        rest = observation["environment_state"][2]
        expert = ExpertPolicy(waypoint_noise=0.003, action_noise=0.005, seed=seed, task="stack_cube")
        expert.reset(observation)
        for _ in range(600):
            observation, reward, terminated, truncated, info = env.step(expert(observation))
            if terminated:
                break
        assert terminated and info["is_success"] and reward == 1.0, seed
        x, y, z = observation["environment_state"][:3]
        assert np.hypot(x - 0.20, y - 0.18) < 0.03 and abs(z - (rest + 0.03)) < 0.003
    env.close()
    # The place_cube scene has no second cube: the same plan sets the red cube down on the pad's
    # bare table, one edge lower than a stack.
    env = gym.make("so101/PlaceCube-v0")
    observation, _ = env.reset(seed=2)
    rest = observation["environment_state"][2]
    expert = ExpertPolicy(seed=2, task="stack_cube")
    expert.reset(observation)
    for _ in range(600):
        observation, *_ = env.step(expert(observation))
    assert abs(observation["environment_state"][2] - rest) < 0.003
    env.close()


def test_the_cameras_show_the_push_target_flat_on_the_table_and_the_green_cube_only_in_their_tasks():
    """push_cube's target is a mark the cameras draw (a 1 mm disc, nothing collides with it);
    stack_cube's green cube is in its scene only. Seen from the front, the disc is wider than
    tall (flat on the table), and the other tasks' pictures show neither."""
    from so101.envs import So101InProcessEnv

    def front(task):
        env = So101InProcessEnv(task=task, cameras={"front": (240, 320)})
        observation, _ = env.reset(seed=3)
        env.close()
        return observation["pixels"]["front"].astype(int)

    plain = front("cube_to_bin")
    green = (38, 158, 64)
    # The parked green cube is in no other task's picture: none of its colour anywhere.
    assert not (np.abs(plain - green).max(axis=2) < 40).any()
    for task, colour in (("push_cube", (235, 235, 225)), ("stack_cube", green)):
        changed = np.abs(front(task) - plain).sum(axis=2) > 30
        rows, columns = np.nonzero(changed)
        assert rows.size > 20, task
        height, width = np.ptp(rows) + 1, np.ptp(columns) + 1
        assert width < 60 and height < 60, (task, height, width)  # one compact object
        if task == "push_cube":
            assert height < 0.8 * width, (height, width)  # a disc seen from above the table (a 6 cm tall one: > 1)
        mean = front(task)[changed].mean(axis=0)
        assert np.abs(mean - colour).max() < 60, (task, mean)
