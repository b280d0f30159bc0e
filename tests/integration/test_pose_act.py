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


def test_pose_act_trains_on_the_recorded_pose_and_acts_from_the_cameras(pose_demos, tmp_path):
    output = tmp_path / "pose_act"
    argv = ["pose_act", "--dataset", str(pose_demos), "--steps", "3", "--batch-size", "4", "--output", str(output)]
    argv += ["--eval", "1", "--eval-backend", "inprocess", "--eval-videos", "0", "--quiet"]
    done = learn(*argv, *[f"--policy-arg={arg}" for arg in TINY], timeout=400)
    assert "success:" in done.stdout, done.stdout

    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == "pose_act"
    # The pose was the estimator's target, not an input: the policy asks for the joints and cameras only.
    assert set(config["input_features"]) == {"observation.state", "observation.images.top", "observation.images.wrist"}
    info = json.loads((output / "eval" / "eval_info.json").read_text())
    assert info["aggregated"]["episodes"] == 1

    # LeRobot's own evaluation, on an env that gives no cube pose.
    assert lerobot_eval_two_small_cameras(checkpoint, tmp_path / "lerobot_eval")["n_episodes"] == 1


def test_a_camera_dataset_without_the_pose_is_refused_before_training(tmp_path):
    dataset = tmp_path / "dataset"
    (dataset / "meta").mkdir(parents=True)
    features = {"observation.state": {"dtype": "float32"}, "observation.images.top": {"dtype": "video"}}
    (dataset / "meta" / "info.json").write_text(json.dumps({"features": features}))
    command = [VENV_BIN / "so101-learn", "pose_act", "--dataset", dataset, "--eval", "0"]
    done = subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=60)
    assert done.returncode != 0 and "without --no-environment-state" in done.stderr, done.stdout + done.stderr
