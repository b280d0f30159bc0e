"""LeRobot's env type `so101_sim` (plugin lerobot_env_so101_sim) with LeRobot's own CLIs: two expert
episodes recorded from the sim and converted by so101-bag-to-lerobot; the dataset's actions,
replayed through the env in LeRobot units, put the cube in the bin again (info["is_success"]); a
tiny ACT trained on the dataset by lerobot-train evaluates on the env during training
(--env_eval_freq) and afterwards with lerobot-eval (eval_info.json, a video)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from harness import TINY_ACT, Probe, SimNode, node_binary, stop_nodes, wait_until
from harness import run_offline as run

from so101.evaluate.episodes import WATCHABLE_HEIGHT

VENV_BIN = Path(sys.executable).parent
SEED = 3  # the sim's seed while recording: the env reset with it puts the cube where episode 0 had it
CAMERA = ("top", 48, 64)  # name, height, width: the dataset's one camera and the env's
ENV_FLAGS = ["--env.type=so101_sim", "--env.cameras={top: [48, 64]}", "--env.episode_length=8"]
REPO_ID = "local/so101_env_test"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """Two expert episodes (one 64x48 camera), recorded and converted into a LeRobot dataset."""

    tmp = tmp_path_factory.mktemp("lerobot_env")
    bags = tmp / "bags"
    name, height, width = CAMERA
    sim = SimNode(
        node_binary(),
        ["--lite", "--speed", "3", "--seed", str(SEED), "--cameras", f"{name}:{width}x{height}", "--camera-rate", "30"],
        tmp / "sim.log",
    )
    nodes = [sim]
    probe = Probe("so101_env_test_probe")
    try:
        nodes.append(SimNode(node_binary("recorder_node"), ["--output", str(bags)], tmp / "recorder.log"))
        probe.wait_for_graph(lambda: probe.node.count_subscribers("/episode/events") >= 1, 20.0, "the recorder", sim)
        expert = SimNode(
            node_binary("teleop_node"), ["--source", "expert", "--sim-time", "--episodes", "2", "--seed", "2"], tmp / "teleop.log"
        )
        nodes.append(expert)
        wait_until(lambda: not expert.alive(), 120.0, "the expert's 2 episodes", sim)
        wait_until(
            lambda: len([d for d in bags.glob("episode_*") if (d / "metadata.yaml").is_file()]) == 2, 20.0, "2 episodes", sim
        )
    finally:
        probe.close()
        problems = stop_nodes(nodes)
    assert not problems, problems
    output = tmp / "dataset"
    done = run([VENV_BIN / "so101-bag-to-lerobot", bags, "--output", output, "--repo-id", REPO_ID, "--quiet"], 300, tmp)
    # The expert may miss a grasp now and then: training takes failed episodes too.
    assert done.returncode == 0 and "2 episode(s)" in done.stdout, done.stdout + done.stderr
    return output


def test_the_datasets_actions_replayed_through_the_env_succeed(dataset):
    """Observations and actions in the dataset's units: the env starts where a successful episode
    started (observation.state) and its actions, sent as LeRobot actions, end in info["is_success"]."""
    import gymnasium as gym
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    from lerobot.envs.configs import EnvConfig

    config = EnvConfig.get_choice_class("so101_sim")(cameras={CAMERA[0]: CAMERA[1:]})
    data = LeRobotDataset(REPO_ID, root=dataset)
    bounds = list(zip(data.meta.episodes["dataset_from_index"], data.meta.episodes["dataset_to_index"]))
    successful = [k for k, (_start, stop) in enumerate(bounds) if bool(data[stop - 1]["next.success"].item())]
    assert successful, "the expert succeeded in no episode"
    episode = successful[0]
    start, stop = bounds[episode]
    frames = data.hf_dataset.select(range(start, stop))
    states = np.stack([np.asarray(s) for s in frames["observation.state"]])
    actions = np.stack([np.asarray(a) for a in frames["action"]])

    env = gym.make(config.gym_id, disable_env_checker=True, **config.gym_kwargs)
    try:
        # The sim's first reset after its start with SEED placed the cube of episode 0, the next one episode 1's.
        observation, info = env.reset(seed=SEED)
        for _ in range(episode):
            observation, info = env.reset()
        assert info["is_success"] is False
        assert observation["pixels"][CAMERA[0]].shape == CAMERA[1:] + (3,)
        # What lerobot-eval films: the camera's own frame, each pixel repeated up to a watchable size.
        factor = -(-WATCHABLE_HEIGHT // CAMERA[1])
        frame = env.render()
        assert frame.shape == (CAMERA[1] * factor, CAMERA[2] * factor, 3) and env.metadata["render_fps"] == 30
        assert np.array_equal(frame[::factor, ::factor], observation["pixels"][CAMERA[0]])
        assert np.abs(observation["agent_pos"] - states[0]).max() < 2.0, (observation["agent_pos"], states[0])
        successes = []
        for action in actions:
            observation, _reward, terminated, truncated, info = env.step(action)
            successes.append(info["is_success"])
            if terminated or truncated:
                break
        assert any(successes) and terminated, f"no success in {len(successes)} replayed steps of {len(actions)}"
        # The arm followed: the last state is near the dataset's state of that frame.
        assert np.abs(observation["agent_pos"] - states[len(successes) - 1]).max() < 10.0
    finally:
        env.close()


def test_lerobot_train_evaluates_on_the_env_and_lerobot_eval_runs_its_policy(dataset, tmp_path):
    train = tmp_path / "train"
    done = run(
        [
            VENV_BIN / "lerobot-train",
            f"--dataset.repo_id={REPO_ID}",
            f"--dataset.root={dataset}",
            *TINY_ACT,
            "--policy.n_vae_encoder_layers=1",
            "--policy.chunk_size=5",
            "--policy.n_action_steps=5",
            *ENV_FLAGS,
            "--env_eval_freq=2",
            "--eval.n_episodes=1",
            "--eval.batch_size=1",
            "--eval.use_async_envs=false",
            "--steps=2",
            "--batch_size=4",
            "--num_workers=0",
            "--save_freq=2",
            "--log_freq=1",
            "--wandb.enable=false",
            f"--output_dir={train}",
        ],
        300,
        tmp_path,
    )
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    assert "Eval policy at step 2" in log, log[-4000:]
    assert "'task_group': 'so101_sim'" in log and "'successes': [False]" in log, log[-4000:]
    videos = list((train / "eval").rglob("*.mp4"))
    assert videos, f"no evaluation video under {train / 'eval'}"
    checkpoint = train / "checkpoints" / "last" / "pretrained_model"
    assert (checkpoint / "model.safetensors").is_file()

    evaluation = tmp_path / "eval"
    done = run(
        [
            VENV_BIN / "lerobot-eval",
            f"--policy.path={checkpoint}",
            "--policy.device=cpu",
            *ENV_FLAGS,
            "--env.randomize=default",
            "--env.servo_params=sts3215",
            "--eval.n_episodes=1",
            "--eval.batch_size=1",
            "--eval.use_async_envs=false",
            "--seed=7",
            f"--output_dir={evaluation}",
        ],
        300,
        tmp_path,
    )
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    info = json.loads((evaluation / "eval_info.json").read_text())
    overall = info["overall"]
    assert overall["n_episodes"] == 1 and overall["pc_success"] in (0.0, 100.0), overall
    tasks = info["per_task"]
    assert [t["task_group"] for t in tasks] == ["so101_sim"], tasks
    successes = tasks[0]["metrics"]["successes"]
    assert len(successes) == 1 and isinstance(successes[0], bool), successes
    # 8 steps of a tiny policy from the home pose cannot put the cube in the bin.
    assert overall["pc_success"] == 0.0 and successes == [False]
    assert overall["video_paths"] and Path(overall["video_paths"][0]).is_file(), overall
    import av

    with av.open(overall["video_paths"][0]) as container:
        frames = [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]
    assert len(frames) >= 8 and frames[0].shape[0] >= WATCHABLE_HEIGHT, (len(frames), frames[0].shape)
    assert frames[-1].std() > 5, "a blank video"
    # LeRobot's CLI set --env.randomize: the first frame is seed 7's randomized scene, not the
    # nominal one (colours, lights and the camera moved).
    from so101.lerobot.adapter import So101LeRobotEnv

    def first_frame(randomize: str) -> np.ndarray:
        env = So101LeRobotEnv(cameras={"top": (48, 64)}, randomize=randomize)
        try:
            env.reset(seed=7)
            return env.render().astype(float)  # enlarged as lerobot-eval films it
        finally:
            env.close()

    filmed = frames[0].astype(float)
    to_randomized = np.abs(filmed - first_frame("default")).mean()
    to_nominal = np.abs(filmed - first_frame("off")).mean()
    assert to_randomized < 0.5 * to_nominal, (to_randomized, to_nominal)
