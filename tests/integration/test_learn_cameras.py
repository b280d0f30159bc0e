"""The camera recipe at toy size, as a user runs it: `so101-learn demos` records expert episodes
seen by two small cameras, without the cube's pose, through the stack; `so101-learn act` trains
ACT from scratch with every augmentation and evaluates it through so101-run-policy and LeRobot's
own lerobot-eval; the GPU recipe's 640x480 frames take a few steps on the CPU. (Apart from
test_learn.py, the state recipes, so the two files' recordings run on two workers at once.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from harness import lerobot_eval_two_small_cameras
from harness import so101_learn as learn

VENV_BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def camera_demos(tmp_path_factory) -> Path:
    """Two expert episodes seen by two small cameras, without the cube's pose (as on a real arm)."""
    output = tmp_path_factory.mktemp("camera_demos")
    argv = ["demos", "--episodes", "2", "--seed", "3", "--lite", "--cameras", "top:32x24,wrist:32x24"]
    done = learn(*argv, "--no-environment-state", "--output", str(output), timeout=240)
    assert "Summary: 2 demonstration(s) recorded" in done.stdout, done.stdout
    return output / "dataset"


def test_the_camera_recipe_trains_from_scratch_with_augmentation_and_evaluates_both_ways(camera_demos, tmp_path):
    output = tmp_path / "act"
    tiny = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
    argv = ["act", "--dataset", str(camera_demos), "--steps", "3", "--batch-size", "4", "--output", str(output)]
    # Every augmentation set, through lerobot-train's parser and LeRobot's loader.
    argv += ["--augment", "colour,shift,blur,noise"]
    argv += ["--eval", "1", "--eval-videos", "1", "--quiet"] + [f"--policy-arg={arg}" for arg in tiny]
    done = learn(*argv, timeout=400)

    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((checkpoint / "config.json").read_text())
    inputs = config["input_features"]
    assert {"observation.images.top", "observation.images.wrist", "observation.state"} == set(inputs), inputs
    assert inputs["observation.images.top"]["shape"] == [3, 24, 32]
    # The backbone learnt from scratch: nothing was (or could be) downloaded.
    assert config["pretrained_backbone_weights"] is None
    transforms = json.loads((checkpoint / "train_config.json").read_text())["dataset"]["image_transforms"]
    assert transforms["enable"] and "affine" not in transforms["tfs"] and "brightness" in transforms["tfs"]
    assert transforms["tfs"]["shift"]["type"] == "RandomAffine" and transforms["tfs"]["shift"]["kwargs"]["translate"] == [
        0.02,
        0.02,
    ]
    assert {"blur", "noise"} <= set(transforms["tfs"])

    info = json.loads((output / "eval" / "eval_info.json").read_text())
    assert info["aggregated"]["episodes"] == 1 and "success:" in done.stdout
    import av

    with av.open(info["per_episode"][0]["video"]) as container:
        frame = next(container.decode(video=0)).to_ndarray(format="rgb24")
    # The policy's two 32x24 cameras side by side, enlarged to a watchable height (x15: 360 rows).
    assert frame.shape == (360, 960, 3), frame.shape

    # The same policy through LeRobot's own evaluation, on the env type with the same cameras.
    overall = lerobot_eval_two_small_cameras(checkpoint, tmp_path / "lerobot_eval")
    assert overall["n_episodes"] == 1 and overall["pc_success"] == 0.0  # 8 steps cannot reach the bin

    # Its failure told apart by so101-bench grasps, replaying the evaluation's failing seed against the expert's.
    numbers = tmp_path / "grasps.json"
    command = [sys.executable, "-m", "so101.bench.grasps", checkpoint, "--failures-of", output / "eval" / "eval_info.json"]
    done = subprocess.run(
        [str(c) for c in command + ["--threads", "1", "--json", numbers]], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads(numbers.read_text())
    assert report["seeds"] == [info["per_episode"][0]["seed"]] and report["policy"]["kinds"]["success"] == 0
    assert report["expert"]["kinds"]["success"] == 1 and "| median distance from the cube at the first closing |" in done.stdout


def test_camera_items_kept_in_memory_train_the_very_weights_of_frames_decoded_at_every_step(camera_demos, tmp_path):
    """The camera recipe keeps each item's decoded frames in memory after its first read and
    applies the augmentation at every read (so101.learn.train_in_memory): over a pass through the
    demonstrations and four batches of the next, with the recipe's loader process, training gives
    the weights lerobot-train itself gives decoding every item at every step (--reread-items)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from safetensors.torch import load_file

    frames = LeRobotDataset("local/demos", root=camera_demos).num_frames
    batch = 32
    steps = frames // batch + 5
    tiny = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
    argv = ["act", "--dataset", str(camera_demos), "--steps", str(steps), "--batch-size", str(batch), "--eval", "0"]
    argv += [f"--policy-arg={arg}" for arg in tiny]
    weights, logs = {}, {}
    for way, extra in (("memory", []), ("reread", ["--reread-items"])):
        done = learn(*argv, *extra, "--output", str(tmp_path / way), timeout=400)
        logs[way] = done.stdout + done.stderr
        weights[way] = load_file(tmp_path / way / "checkpoints" / "last" / "pretrained_model" / "model.safetensors")
    assert "-m so101.learn.train_in_memory" in logs["memory"] and "items is kept in memory" in logs["memory"]
    assert "its image augmentation applied at every read" in logs["memory"] and "--num_workers=1" in logs["memory"]
    assert "bin/lerobot-train " in logs["reread"] and "kept in memory" not in logs["reread"]
    differing = [name for name in weights["memory"] if not weights["memory"][name].equal(weights["reread"][name])]
    assert weights["memory"].keys() == weights["reread"].keys() and not differing, differing


def test_the_gpu_recipe_at_the_main_jobs_640x480_takes_a_few_steps_on_the_cpu(camera_demos, tmp_path):
    """The recipe docs/learning.md gives for a GPU, on images of the main job's size: the camera
    demos' first bag converted at 640x480 (enlarged: the shape is what counts here, not the content;
    one camera of the two, as the cost of both is twice the time for the same check), then the same
    `so101-learn act` for two steps on the CPU."""
    dataset = tmp_path / "dataset640"
    # One episode is enough for two steps of training, and 5 frames a second of it (encoding 640x480
    # frames is what takes the time: 10 s at the recording's 30, 0.3 s at 5).
    episode = camera_demos.parent / "bags" / "episode_000000"
    command = [str(VENV_BIN / "so101-bag-to-lerobot"), str(episode), "--output", str(dataset), "--fps", "5"]
    command += ["--image-size", "640x480", "--cameras", "top", "--no-environment-state", "--quiet"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    output = tmp_path / "act640"
    learn(
        "act", "--dataset", str(dataset), "--steps", "2", "--batch-size", "2", "--eval", "0", "--output", str(output), timeout=400
    )
    config = json.loads((output / "checkpoints" / "last" / "pretrained_model" / "config.json").read_text())
    assert config["input_features"]["observation.images.top"]["shape"] == [3, 480, 640]
    assert config["pretrained_backbone_weights"] is None


def test_bf16_trains_the_camera_policy_channels_last_and_saves_checkpoints_lerobot_reads(camera_demos, tmp_path):
    """`--bf16` on a camera dataset: LeRobot's mixed precision with the convolutions in
    channels_last (so101.learn.channels_last), checkpoints LeRobot writes (the optimizer's
    channels_last moments made contiguous, which safetensors requires; reading them back is
    test_channels_last's) and a policy so101-run-policy loads."""
    from safetensors.torch import load_file

    from so101.evaluate.policy import StackPolicy

    output = tmp_path / "act_bf16"
    tiny = ["--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1"]
    argv = ["act", "--dataset", str(camera_demos), "--steps", "2", "--batch-size", "4", "--eval", "0", "--bf16"]
    done = learn(*argv, "--save-every", "1", "--output", str(output), *[f"--policy-arg={arg}" for arg in tiny], timeout=400)
    assert "convolutions train in channels_last" in done.stdout + done.stderr
    for step in ("000001", "000002"):
        assert load_file(output / "checkpoints" / step / "training_state" / "optimizer_state.safetensors")
    checkpoint = output / "checkpoints" / "last" / "pretrained_model"
    assert json.loads((checkpoint / "config.json").read_text())["use_amp"] is True
    assert {camera.name for camera in StackPolicy(str(checkpoint)).cameras} == {"top", "wrist"}
