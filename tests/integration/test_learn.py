"""The learning recipes at toy size, as a user runs them: `so101-learn demos` records expert
episodes through the stack (launcher, sim node, teleop_node's expert, recorder) and converts them;
`so101-learn act` / `diffusion` train on that dataset with lerobot-train (a few steps, shrunk
networks) and evaluate the policy through so101-run-policy in lockstep with the sim node. What a
user reads is checked: the dataset LeRobot loads (with the cube's pose), the checkpoint, the
evaluation's eval_info.json with its 95 % interval, and the summaries."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

VENV_BIN = Path(sys.executable).parent


def learn(*argv: str, timeout: float) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}
    done = subprocess.run([str(VENV_BIN / "so101-learn"), *argv], capture_output=True, text=True, timeout=timeout, env=env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


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
        ("diffusion", ["--policy.down_dims=[16,32,64]", "--policy.diffusion_step_embed_dim=16"]),
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
