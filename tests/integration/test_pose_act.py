"""The robust camera recipe's policy type at toy size, as a user runs it: `so101-learn demos`
records expert episodes seen by two small cameras with the cube's pose (the estimator's target),
in-process; `so101-learn pose_act` trains through lerobot-train, which finds the type through its
plugin, and evaluates it through so101-run-policy; LeRobot's own lerobot-eval runs the policy on
an env that gives no cube pose, as a real arm gives none."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from harness import lerobot_eval_two_small_cameras
from harness import so101_learn as learn

VENV_BIN = Path(sys.executable).parent
TINY = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
TINY += ["--policy.estimator_channels=8", "--policy.estimator_keypoints=4", "--policy.estimator_hidden=16"]


@pytest.fixture(scope="module")
def pose_demos(tmp_path_factory) -> Path:
    """Two expert episodes seen by two small cameras, with the cube's pose recorded."""
    output = tmp_path_factory.mktemp("pose_demos")
    argv = ["demos", "--backend", "inprocess", "--episodes", "2", "--seed", "5", "--lite"]
    done = learn(*argv, "--cameras", "top:32x24,wrist:32x24", "--randomize", "--output", str(output), timeout=240)
    assert "2 successful" in done.stdout and "2 kept" in done.stdout, done.stdout
    return output / "dataset"


@pytest.fixture(scope="module")
def trained(pose_demos, tmp_path_factory) -> Path:
    """pose_act at toy size trained 3 steps on the two episodes and evaluated over one: its output."""
    output = tmp_path_factory.mktemp("trained") / "pose_act"
    argv = ["pose_act", "--dataset", str(pose_demos), "--steps", "3", "--batch-size", "4", "--output", str(output)]
    argv += ["--eval", "1", "--eval-backend", "inprocess", "--eval-videos", "0", "--quiet"]
    done = learn(*argv, *[f"--policy-arg={arg}" for arg in TINY], timeout=400)
    assert "success:" in done.stdout, done.stdout
    return output


def test_pose_act_trains_on_the_recorded_pose_and_acts_from_the_cameras(pose_demos, trained, tmp_path):
    output = trained
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == "pose_act"
    # The pose was the estimator's target, not an input: the policy asks for the joints and cameras only.
    assert set(config["input_features"]) == {"observation.state", "observation.images.top", "observation.images.wrist"}
    info = json.loads((output / "eval" / "eval_info.json").read_text())
    assert info["aggregated"]["episodes"] == 1

    # LeRobot's own evaluation, on an env that gives no cube pose.
    assert lerobot_eval_two_small_cameras(checkpoint, tmp_path / "lerobot_eval")["n_episodes"] == 1

    # The estimator's benchmark: every closed-loop period and every demonstration frame estimated.
    numbers = tmp_path / "pose_estimate.json"
    command = [sys.executable, "-m", "so101.bench.pose_estimate", checkpoint, "--dataset", pose_demos]
    command += ["--episodes", "1", "--anchor-episodes", "1", "--threads", "1", "--json", numbers]
    done = subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads(numbers.read_text())
    dataset_info = json.loads((pose_demos / "meta" / "info.json").read_text())
    assert report["closed_loop"][-1]["frames"] > 0 and report["closed_loop"][-1]["mean_mm"] > 0
    assert sum(row["frames"] for row in report["closed_loop"][:-1]) == report["closed_loop"][-1]["frames"]
    assert 0 < report["demonstrations"][-1]["frames"] < dataset_info["total_frames"]  # one of its two episodes
    assert "| all frames |" in done.stdout


def test_dagger_the_policy_drives_the_expert_labels_and_training_goes_on_from_its_weights(pose_demos, trained, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from safetensors.torch import load_file

    checkpoint = trained / "checkpoints" / "last" / "pretrained_model"
    argv = ["demos", "--backend", "inprocess", "--episodes", "1", "--seed", "6", "--lite", "--keep-failures", "--randomize"]
    argv += ["--driver", str(checkpoint), "--after", str(pose_demos)]

    # Demonstrations whose features differ from the dataset they would follow are refused first.
    done = subprocess.run(
        [str(VENV_BIN / "so101-learn"), *argv, "--cameras", "top:32x24", "--output", str(tmp_path / "refused")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode != 0 and "has the features" in done.stderr, done.stdout + done.stderr
    assert not (tmp_path / "refused" / "dataset").exists()

    done = learn(*argv, "--cameras", "top:32x24,wrist:32x24", "--output", str(tmp_path / "dagger"), timeout=240)
    assert "1 kept" in done.stdout and "after the 2 episode(s)" in done.stdout, done.stdout
    grown_root = tmp_path / "dagger" / "dataset"
    grown = LeRobotDataset("local/so101_demos", root=grown_root)
    base = LeRobotDataset("local/so101_demos", root=pose_demos)
    assert grown.meta.total_episodes == 3 and grown.meta.total_frames > base.meta.total_frames
    for index in (0, base.meta.total_frames - 1):  # the demonstrations come first, as they were
        assert (grown[index]["observation.state"] == base[index]["observation.state"]).all()
        assert (grown[index]["action"] == base[index]["action"]).all()
    settings = json.loads((grown_root / "meta" / "so101_simulation.json").read_text())["episodes"]
    assert [entry["episode_index"] for entry in settings] == [0, 1, 2]

    # Training goes on from the policy's weights (its step count), the joints normalized as the
    # grown dataset's statistics say, as the preprocessor normalizes them.
    output = tmp_path / "fine_tuned"
    argv = ["pose_act", "--dataset", str(grown_root), "--init", str(checkpoint), "--steps", "2", "--batch-size", "4"]
    done = learn(*argv, "--eval", "0", "--quiet", "--output", str(output), *[f"--policy-arg={arg}" for arg in TINY], timeout=400)
    assert "trained 2 steps (batch 4) from" in done.stdout, done.stdout
    before = load_file(str(checkpoint / "model.safetensors"))
    after = load_file(str(output / "checkpoints" / "last" / "pretrained_model" / "model.safetensors"))
    assert int(after["trained_steps"]) == int(before["trained_steps"]) + 2 == 5
    grown_mean = np.asarray(grown.meta.stats["observation.state"]["mean"], dtype=np.float32).reshape(-1)
    assert np.allclose(after["state_mean"].numpy(), grown_mean, atol=1e-5)
    assert not np.allclose(after["state_mean"].numpy(), before["state_mean"].numpy(), atol=1e-5)


def test_a_camera_dataset_without_the_pose_is_refused_before_training(tmp_path):
    dataset = tmp_path / "dataset"
    (dataset / "meta").mkdir(parents=True)
    features = {"observation.state": {"dtype": "float32"}, "observation.images.top": {"dtype": "video"}}
    (dataset / "meta" / "info.json").write_text(json.dumps({"features": features}))
    command = [VENV_BIN / "so101-learn", "pose_act", "--dataset", dataset, "--eval", "0"]
    done = subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=60)
    assert done.returncode != 0 and "without --no-environment-state" in done.stderr, done.stdout + done.stderr
