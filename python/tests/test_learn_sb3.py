"""so101-learn's Stable-Baselines3 / imitation recipes at toy size, in-process (no ROS, no DDS):
the learning wrappers (flat observation order, relative actions within the max step and the joint
limits), behaviour cloning through imitation (installed --no-deps next to SB3 2.9 and gymnasium
1.x: this is the test that the combination works) whose saved policy `so101-learn eval` loads,
SAC's checkpoints, progress.csv, success.png, --resume and VecNormalize statistics, and --help."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from so101.envs import action_space, make_env, observation_space
from so101.learn import cli, eval_recipe, sb3_sac
from so101.learn.wrappers import (
    ELAPSED,
    FLAT_KEYS,
    EnvSettings,
    FlatObservation,
    RelativeJointTargets,
    flatten,
    relative_action,
)

LIMITS = action_space()


class PerfectArm(gym.Env):
    """Reaches every target exactly; remembers what it was commanded."""

    def __init__(self, start):
        self.observation_space = observation_space({})
        self.action_space = LIMITS
        self.start = np.asarray(start, dtype=np.float64)
        self.commands: list[np.ndarray] = []

    def _observation(self):
        return {"agent_pos": self.positions.copy(), "agent_vel": np.zeros(6), "environment_state": np.zeros(7)}

    def reset(self, *, seed=None, options=None):
        self.positions = self.start.copy()
        return self._observation(), {}

    def step(self, action):
        self.commands.append(np.asarray(action, dtype=np.float64))
        self.positions = self.commands[-1].copy()
        return self._observation(), 0.0, False, False, {"is_success": False}


def test_the_flat_observation_is_positions_velocities_cube_pose_then_the_elapsed_time():
    assert FLAT_KEYS == ("agent_pos", "agent_vel", "environment_state")
    raw = make_env("cube_to_bin")
    env = EnvSettings(elapsed_time=True).make()
    assert env.observation_space.shape == (20,) and env.action_space.shape == (6,)
    flat, _ = env.reset(seed=4)
    expected, _ = raw.reset(seed=4)
    assert np.allclose(flat[:6], expected["agent_pos"]) and np.allclose(flat[6:12], expected["agent_vel"])
    assert np.allclose(flat[12:19], expected["environment_state"]) and flat[19] == 0.0
    for _ in range(3):
        flat, *_ = env.step(np.zeros(6, dtype=np.float32))
    assert flat[19] == pytest.approx(3 / 30)
    assert flat[14] == pytest.approx(expected["environment_state"][2], abs=0.01), "the cube's height, where it rests"
    # Standardized: (x - shift) / scale, element by element.
    shift, scale = np.arange(19, dtype=np.float32), np.linspace(1, 2, 19, dtype=np.float32)
    standardized = FlatObservation(make_env("touch_cube"), FLAT_KEYS, shift, scale)
    observation, _ = standardized.reset(seed=4)
    assert np.allclose(observation, (flatten(expected) - shift) / scale, atol=1e-5)
    assert np.allclose(
        EnvSettings(observation_shift=shift.tolist(), observation_scale=scale.tolist()).flat(expected), observation
    )
    raw.close()
    env.close()


def test_relative_actions_move_the_target_by_at_most_the_max_step_within_the_joint_limits():
    max_step = np.array([0.05, 0.05, 0.1, 0.1, 0.2, 0.3])
    arm = PerfectArm(start=LIMITS.high - 0.02)  # near the upper limits: +1 would cross them
    env = RelativeJointTargets(arm, max_step)
    assert env.action_space.low.tolist() == [-1] * 6 and env.action_space.high.tolist() == [1] * 6
    observation, _ = env.reset()
    observation, *_ = env.step(np.ones(6))
    assert np.allclose(arm.commands[-1], LIMITS.high), "clipped to the limits"
    rng = np.random.default_rng(0)
    for _ in range(200):
        before = observation["agent_pos"]
        action = rng.uniform(-2, 2, size=6)  # out of range too: clipped to [-1, 1]
        observation, *_ = env.step(action)
        moved = arm.commands[-1] - before
        assert np.all(np.abs(moved) <= max_step + 1e-6)
        assert np.all(arm.commands[-1] >= LIMITS.low - 1e-6) and np.all(arm.commands[-1] <= LIMITS.high + 1e-6)
        inside = (before + np.clip(action, -1, 1) * max_step > LIMITS.low) & (
            before + np.clip(action, -1, 1) * max_step < LIMITS.high
        )
        assert np.allclose(moved[inside], (np.clip(action, -1, 1) * max_step)[inside], atol=1e-6)
    # Demonstrations' absolute targets become actions that reach them when within a step.
    positions = observation["agent_pos"]
    target = np.clip(positions + max_step * np.array([0.5, -0.25, 0.0, 1.0, -1.0, 0.1]), LIMITS.low, LIMITS.high)
    assert np.allclose(env.target(relative_action(target, positions, max_step)), target, atol=1e-6)
    assert np.all(np.abs(relative_action(positions + 10, positions, max_step)) == 1.0)


def test_bc_through_imitation_learns_from_expert_demos_and_so101_learn_eval_runs_the_saved_policy(tmp_path, capsys):
    output = tmp_path / "bc"
    args = ["bc", "--demos", "3", "--epochs", "20", "--batch-size", "64", "--hidden", "64", "64", "--eval", "0"]
    assert cli.main([*args, "--output", str(output), "--quiet"]) == 0
    record = json.loads((output / "so101_learn.json").read_text())
    assert record["algorithm"] == "bc" and (output / record["model"]).is_file()
    demos = record["demonstrations"]
    assert demos["kept"] + demos["dropped"] == 3 and demos["kept"] >= 1
    # ~200 steps an episode until the cube lies in the bin.
    assert 100 * demos["kept"] < demos["transitions"] < 400 * demos["kept"]
    assert record["training"]["loss_after"] < record["training"]["loss_before"] - 1.0, record["training"]
    env = record["env"]
    assert env["observation"] == [*FLAT_KEYS, ELAPSED] and len(env["observation_shift"]) == 20
    assert all(scale > 0 for scale in env["observation_scale"])
    # ReLU units from PyTorch's initialization: SB3's tanh and orthogonal start cloned a policy
    # that stalled short of the grasp on the STS3215 servos (so101.learn.sb3_bc).
    from stable_baselines3.common.policies import ActorCriticPolicy

    saved = ActorCriticPolicy.load(str(output / record["model"]), device="cpu")
    assert saved.activation_fn is torch.nn.ReLU and not saved.ortho_init
    assert any(isinstance(layer, torch.nn.ReLU) for layer in saved.mlp_extractor.policy_net)

    assert eval_recipe.find_saved(str(output)) is not None and eval_recipe.find_saved(str(output / "policy.pth")) is not None
    assert cli.main(["eval", str(output), "--eval", "2", "--seed", "1000", "--output", str(tmp_path / "eval"), "--quiet"]) == 0
    report = json.loads((tmp_path / "eval" / "eval_info.json").read_text())
    assert report["aggregated"]["algorithm"] == "bc" and report["aggregated"]["episodes"] == 2
    assert [episode["seed"] for episode in report["per_episode"]] == [1000, 1001]
    assert all(0 < episode["steps"] <= 600 for episode in report["per_episode"])
    assert "2 episode(s): success" in capsys.readouterr().out


def progress(output: Path) -> list[dict]:
    return sb3_sac.read_progress(output / "progress.csv")


def statistics(checkpoint: Path):
    import pickle

    with (checkpoint / sb3_sac.VEC_NORMALIZE_FILE).open("rb") as f:
        return pickle.load(f).obs_rms


def test_sac_checkpoints_resumes_from_the_newest_and_keeps_its_vecnormalize_statistics(tmp_path):
    from stable_baselines3 import SAC

    output = tmp_path / "sac"
    common = ["--task", "touch_cube", "--learning-starts", "50", "--checkpoint-every", "150", "--eval-every", "150"]
    common += ["--eval-episodes", "1", "--hidden", "32", "32", "--batch-size", "32", "--output", str(output), "--quiet"]
    assert cli.main(["sac", "--steps", "300", "--vec-normalize", *common]) == 0
    first = sb3_sac.checkpoints(output)
    assert [path.name for path in first] == ["step_000000150", "step_000000300"]
    for folder in first:
        assert (folder / "model.zip").is_file() and (folder / "vecnormalize.pkl").is_file()
    assert not (first[0] / "replay_buffer.pkl").exists() and (first[1] / "replay_buffer.pkl").is_file()
    assert [row["timesteps"] for row in progress(output)] == [150, 300]
    assert (output / "success.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    counted = statistics(first[1]).count
    assert counted >= 300, "the statistics saw every training observation"

    # The checkpoint's model with its statistics is what was evaluated at that step.
    row = progress(output)[-1]
    assert cli.main(["eval", str(first[1]), "--eval", "1", "--seed", "1000", "--output", str(tmp_path / "eval"), "--quiet"]) == 0
    report = json.loads((tmp_path / "eval" / "eval_info.json").read_text())["aggregated"]
    assert report["algorithm"] == "sac" and report["avg_sum_reward"] == pytest.approx(row["mean_reward"], abs=1e-6)

    # Resume to 450: steps go on from 300 with the replay buffer and statistics of that checkpoint.
    assert cli.main(["sac", "--steps", "450", "--resume", *common]) == 0
    assert [row["timesteps"] for row in progress(output)] == [150, 300, 450]
    newest = sb3_sac.checkpoints(output)[-1]
    assert newest.name == "step_000000450" and not (first[1] / "replay_buffer.pkl").exists()
    model = SAC.load(newest / "model.zip", device="cpu")
    assert model.num_timesteps == 450
    model.load_replay_buffer(newest / "replay_buffer.pkl")
    assert model.replay_buffer.size() == 450, "the first run's transitions are still there"
    assert statistics(newest).count >= counted + 150, "the statistics went on, not restarted"
    assert not np.allclose(statistics(newest).mean, statistics(first[1]).mean)
    with pytest.raises(SystemExit, match="holds a run already"):
        cli.main(["sac", "--steps", "450", *common])


def test_bc_continued_by_sac_starts_from_the_clone_with_the_demonstrations_in_its_replay_buffer(tmp_path, capsys):
    from stable_baselines3 import SAC

    output = tmp_path / "bc"
    args = ["bc", "--demos", "2", "--epochs", "30", "--batch-size", "64", "--hidden", "64", "64", "--eval", "0"]
    args += ["--continue-with-sac", "60", "--critic-warmup", "20", "--sac-eval-every", "60", "--sac-eval-episodes", "1"]
    args += ["--sac-n-envs", "2"]
    assert cli.main([*args, "--output", str(output), "--quiet"]) == 0
    bc = json.loads((output / "so101_learn.json").read_text())
    sac = json.loads((output / "sac" / "so101_learn.json").read_text())
    assert sac["algorithm"] == "sac" and sac["started_from"] == "bc" and sac["env"]["dense_reward"]
    # The same observation and standardization as the clone was trained on.
    assert sac["env"]["observation_shift"] == bc["env"]["observation_shift"]
    transitions = bc["demonstrations"]["transitions"]
    buffered = transitions - transitions % 2  # two worlds: the buffer takes transitions in pairs
    assert sac["training"]["demonstration_transitions"] == buffered and sac["training"]["n_envs"] == 2
    assert sac["training"]["env_steps_per_s"] > 0 and sac["training"]["gradient_steps_per_s"] > 0
    # Step 0 is the clone's own evaluation, before SAC took a step.
    assert [row["timesteps"] for row in progress(output / "sac")] == [0, 60]
    model = SAC.load(output / "sac" / "model.zip", device="cpu")
    model.load_replay_buffer(sb3_sac.checkpoints(output / "sac")[-1] / "replay_buffer.pkl")
    assert model.replay_buffer.size() * 2 == buffered + 60, "the demonstrations stay in the buffer"
    assert "gradient steps/s" in capsys.readouterr().out
    assert cli.main(["eval", str(output / "sac"), "--eval", "1", "--output", str(tmp_path / "eval"), "--quiet"]) == 0


def test_sac_actor_updates_keep_pulling_towards_the_demonstrations(tmp_path):
    import torch
    from imitation.data.types import TransitionsWithRew

    from so101.learn import bc_to_sac

    settings = EnvSettings(task="cube_to_bin", dense_reward=True)
    args = bc_to_sac.sac_arguments(
        argparse.Namespace(
            continue_with_sac=10,
            sac_n_envs=1,
            sac_eval_every=10,
            sac_eval_episodes=1,
            eval_seed=0,
            seed=0,
            quiet=True,
            hidden=[32],
        )
    )
    model = sb3_sac.new_model(args, sb3_sac.make_vec_env(settings, 1, 0))
    rng = np.random.default_rng(0)
    observations = rng.normal(size=(64, 19)).astype(np.float32)
    actions = np.clip(0.5 * observations[:, :6], -0.9, 0.9)  # something an MLP can fit
    transitions = TransitionsWithRew(
        observations, actions, np.array([{}] * 64), observations, np.zeros(64, bool), np.zeros(64, np.float32)
    )

    def loss() -> float:
        with torch.no_grad():
            return float(bc_to_sac.cloning_loss(model.actor, torch.tensor(observations), torch.tensor(actions)))

    def updates(count: int) -> None:
        for _ in range(count):  # SAC's own sequence for an actor update whose critic term is zero
            model.actor.optimizer.zero_grad()
            model.actor.optimizer.step()

    before = loss()
    updates(10)
    assert loss() == before, "SB3's own optimizer: no gradient, no change"
    bc_to_sac.keep_cloning(model, transitions, weight=1.0, seed=0)
    updates(300)
    assert loss() < 0.5 * before


def test_lerobot_policies_go_to_so101_run_policy_inside_a_network_namespace(tmp_path):
    policy = tmp_path / "pretrained_model"
    policy.mkdir()
    (policy / "config.json").write_text(json.dumps({"type": "act"}))
    assert eval_recipe.find_saved(str(policy)) is None
    args = cli.parser().parse_args(["eval", str(policy), "--eval", "7", "--seed", "3", "--lite", "--episode-time", "9"])
    command = eval_recipe.lerobot_eval_command(args, "out")
    assert command[command.index("-m") + 1] == "so101.evaluate.run_policy" and str(policy) in command
    for option in ("--eval=7", "--seed=3", "--output=out", "--backend=ros", "--episode-time=9.0", "--videos=0", "--lite"):
        assert option in command
    # Outside a network namespace (as here) the runner is put inside one.
    assert Path(command[0]).name == "isolated"


@pytest.mark.parametrize("recipe", [None, *cli.RECIPES])
def test_help_of_so101_learn_and_each_recipe(recipe, capsys):
    with pytest.raises(SystemExit) as exit:
        cli.main([recipe, "--help"] if recipe else ["--help"])
    assert exit.value.code == 0
    assert f"so101-learn {recipe or ''}".strip() in capsys.readouterr().out


def test_the_so101_learn_command_is_installed():
    script = Path(sys.executable).parent / "so101-learn"
    done = subprocess.run([str(script), "bc", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "--demos" in done.stdout and "imitation" in done.stdout
