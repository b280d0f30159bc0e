"""The learning recipes at toy size, as a user runs them: `so101-learn demos` records expert
episodes through the stack (launcher, sim node, teleop_node's expert, recorder) and converts them;
`so101-learn act` / `diffusion` train on that dataset with lerobot-train (a few steps, shrunk
networks) and evaluate the policy through so101-run-policy in lockstep with the sim node. What a
user reads is checked: the dataset LeRobot loads (with the cube's pose), the checkpoint, the
evaluation's eval_info.json with its 95 % interval, and the summaries. The camera recipe:
test_learn_cameras.py."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from harness import so101_learn as learn


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    output = tmp_path_factory.mktemp("demos")
    done = learn("demos", "--episodes", "2", "--seed", "3", "--output", str(output), timeout=180)
    assert done.stdout.count("recorded episode_") == 2, done.stdout
    assert "Summary: 2 demonstration(s) recorded" in done.stdout
    return output / "dataset"


def test_demos_are_a_lerobot_dataset_with_the_cube_pose(demos):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("local/demos", root=demos)
    assert 1 <= dataset.meta.total_episodes <= 2  # failed expert episodes are left out
    frame = dataset[0]
    assert tuple(frame["observation.environment_state"].shape) == (7,)
    assert tuple(frame["observation.state"].shape) == (6,)
    # The cube rests on the table at the start (world frame, m): z about 0.77.
    assert 0.7 < float(frame["observation.environment_state"][2]) < 0.85


@pytest.mark.parametrize(
    "recipe,tiny",
    [
        (
            "act",
            ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"],
        ),
        # Two denoising steps per action chunk instead of 100: the evaluation's 1200 periods in seconds.
        (
            "diffusion",
            ["--policy.down_dims=[16,32,64]", "--policy.diffusion_step_embed_dim=16", "--policy.num_inference_steps=2"],
        ),
    ],
)
def test_a_recipe_trains_on_the_demos_and_evaluates_through_the_runner(demos, recipe, tiny, tmp_path):
    output = tmp_path / recipe
    argv = [recipe, "--dataset", str(demos), "--steps", "3", "--batch-size", "4", "--output", str(output)]
    argv += ["--eval", "2", "--eval-seed", "1000", "--eval-videos", "1", "--quiet"] + [f"--policy-arg={arg}" for arg in tiny]
    done = learn(*argv, timeout=400)

    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == recipe
    assert "observation.environment_state" in config["input_features"]
    # The shrunk network came through, over the recipe's preset.
    assert (config.get("dim_model") == 32) if recipe == "act" else (config["down_dims"] == [16, 32, 64])

    if recipe == "diffusion":
        assert_actions_within_the_samplers_clip_range(checkpoint, config, demos)

    info = json.loads((output / "eval" / "eval_info.json").read_text())
    aggregated = info["aggregated"]
    assert aggregated["episodes"] == 2 and aggregated["backend"] == "ros"
    assert [episode["seed"] for episode in info["per_episode"]] == [1000, 1001]
    low, high = aggregated["pc_success_ci95"]
    assert 0 <= low <= aggregated["pc_success"] <= high <= 100
    videos = sorted(path.name for path in (output / "eval" / "videos").iterdir())
    assert videos == ["episode_000_seed1000.mp4"], videos
    assert f"Summary: {recipe} trained 3 steps" in done.stdout
    assert "success:" in done.stdout and "over 2 episodes" in done.stdout


def test_two_processes_train_one_policy_through_accelerate_on_the_cpu(demos, tmp_path):
    """LeRobot's multi-GPU path (accelerate launch, DDP), here on the CPU's gloo backend: both
    processes step, each on its own batch, and the main one writes one checkpoint."""
    output = tmp_path / "ddp"
    tiny = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
    argv = ["act", "--dataset", str(demos), "--steps", "3", "--batch-size", "4", "--num-processes", "2", "--eval", "0"]
    done = learn(*argv, "--output", str(output), *[f"--policy-arg={arg}" for arg in tiny], timeout=300)
    log = done.stdout + done.stderr
    assert "Effective batch size: 4 x 2 = 8" in log, log[-3000:]
    assert "-m so101.learn.train_in_memory" in log and "items is kept in memory" in log, log[-3000:]
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    assert json.loads((checkpoint / "config.json").read_text())["dim_model"] == 32
    assert (checkpoint / "model.safetensors").is_file()


@pytest.mark.parametrize("loading", [[], ["--reread-items"]], ids=["items-in-memory", "lerobot-train-loading"])
def test_an_interrupted_training_resumes_to_the_weights_of_an_uninterrupted_one(demos, tmp_path, loading):
    """A run stopped between checkpoints (its last checkpoint is step 2 of 4) continues with
    --resume from that checkpoint (weights, optimizer, learning-rate schedule, data order) to the
    very weights the run reached without a stop, loading its items as it began: kept in memory
    (the default), or read at every step by lerobot-train's loader process (--reread-items)."""
    from safetensors.torch import load_file

    output = tmp_path / "act"
    tiny = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
    argv = ["act", "--dataset", str(demos), "--steps", "4", "--batch-size", "4", "--save-every", "2", "--eval", "0"]
    learn(*argv, *loading, "--output", str(output), *[f"--policy-arg={arg}" for arg in tiny], timeout=300)
    checkpoints = output / "checkpoints"
    # Each checkpoint says how its run loads its items (what --resume reads).
    assert (checkpoints / "000002" / "so101_items_in_memory.json").is_file() == (not loading)
    uninterrupted = load_file(checkpoints / "000004" / "pretrained_model" / "model.safetensors")
    # What a kill between the checkpoints of steps 2 and 4 leaves.
    shutil.rmtree(checkpoints / "000004")
    (checkpoints / "last").unlink()
    (checkpoints / "last").symlink_to("000002")

    done = learn("act", "--resume", str(output), "--eval", "0", timeout=300)
    assert "trained to step 4 (batch 4), resumed from step 2: 2 steps" in done.stdout, done.stdout[-2000:]
    if loading:
        assert "bin/lerobot-train " in done.stdout and "--num_workers=1" in done.stdout, done.stdout[-2000:]
    else:
        assert "-m so101.learn.train_in_memory" in done.stdout and "--num_workers=0" in done.stdout, done.stdout[-2000:]
    assert os.readlink(checkpoints / "last") == "000004"
    resumed = load_file(checkpoints / "000004" / "pretrained_model" / "model.safetensors")
    assert resumed.keys() == uninterrupted.keys()
    differing = [name for name in resumed if not resumed[name].equal(uninterrupted[name])]
    assert not differing, differing
    # The checkpoint of step 2 is not where it ended: training went on from it.
    halfway = load_file(checkpoints / "000002" / "pretrained_model" / "model.safetensors")
    assert any(not halfway[name].equal(resumed[name]) for name in resumed)


def test_items_kept_in_memory_train_the_very_weights_of_items_read_at_every_step(demos, tmp_path):
    """A dataset without cameras keeps its items in memory after their first read
    (so101.learn.train_in_memory): over two passes through the demonstrations, training gives the
    weights lerobot-train itself gives reading every item at every step (--reread-items), both
    loading in the step. (A loader process alone changes lerobot-train's weights from the same
    seed: every tensor differed after 25 steps.)"""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from safetensors.torch import load_file

    frames = LeRobotDataset("local/demos", root=demos).num_frames
    batch = 64
    steps = 2 * frames // batch + 1
    tiny = ["--policy.down_dims=[16,32,64]", "--policy.diffusion_step_embed_dim=16"]
    argv = ["diffusion", "--dataset", str(demos), "--steps", str(steps), "--batch-size", str(batch), "--eval", "0"]
    argv += [f"--policy-arg={arg}" for arg in tiny]
    weights, logs = {}, {}
    for way, extra in (("memory", []), ("reread", ["--reread-items", "--loader-workers", "0"])):
        done = learn(*argv, *extra, "--output", str(tmp_path / way), timeout=300)
        logs[way] = done.stdout + done.stderr
        weights[way] = load_file(tmp_path / way / "checkpoints" / "last" / "pretrained_model" / "model.safetensors")
    assert "-m so101.learn.train_in_memory" in logs["memory"] and "items is kept in memory" in logs["memory"]
    assert "bin/lerobot-train " in logs["reread"] and "kept in memory" not in logs["reread"]
    differing = [name for name in weights["memory"] if not weights["memory"][name].equal(weights["reread"][name])]
    assert weights["memory"].keys() == weights["reread"].keys() and not differing, differing


def assert_actions_within_the_samplers_clip_range(checkpoint: Path, config: dict, dataset: Path) -> None:
    """Diffusion's sampler clips every denoised action chunk to +-clip_sample_range in normalised
    units: LeRobot's own preprocessor, as saved with the policy, must put the demonstrations'
    actions inside it, or the policy can never command them (why it succeeded 0 % of the time)."""
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from so101.evaluate.policy import StackPolicy

    frames = LeRobotDataset("local/demos", root=dataset).hf_dataset
    batch = {
        key: torch.stack([frame[key] for frame in frames])
        for key in ("action", "observation.state", "observation.environment_state")
    }
    normalised = StackPolicy(str(checkpoint), device="cpu").preprocessor(batch)["action"]
    assert config["clip_sample"]
    assert float(normalised.abs().max()) <= config["clip_sample_range"] + 1e-5, normalised.abs().max(dim=0)
