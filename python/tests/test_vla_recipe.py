"""The VLA recipes' pure parts: which pretrained input each camera feeds, the lerobot-train command,
and which stack cameras a fine-tuned policy takes at what size (the end-to-end run with a tiny
SmolVLA is tests/integration/test_vla.py)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from so101.evaluate.policy import CameraInput, PolicyError, camera_inputs
from so101.learn import vla

PRETRAINED = [f"observation.images.camera{i}" for i in (1, 2, 3)]
TOP, WRIST = "observation.images.top", "observation.images.wrist"


def test_cameras_take_the_free_pretrained_inputs_in_order():
    assert vla.rename_map([TOP, WRIST], PRETRAINED, None) == {TOP: PRETRAINED[0], WRIST: PRETRAINED[1]}


def test_a_camera_named_as_an_input_keeps_it():
    inputs = [TOP, "observation.images.side"]
    assert vla.rename_map([TOP, WRIST], inputs, None) == {WRIST: "observation.images.side"}


def test_the_user_s_map_wins_and_is_checked():
    assert vla.rename_map([TOP, WRIST], PRETRAINED, "top=camera3,wrist=camera1") == {TOP: PRETRAINED[2], WRIST: PRETRAINED[0]}
    with pytest.raises(SystemExit, match="cameras the dataset lacks"):
        vla.rename_map([TOP], PRETRAINED, "front=camera1")
    with pytest.raises(SystemExit, match="inputs the pretrained model lacks"):
        vla.rename_map([TOP], PRETRAINED, "top=camera9")
    with pytest.raises(SystemExit, match="CAMERA=INPUT"):
        vla.rename_map([TOP], PRETRAINED, "top")


def test_more_cameras_than_inputs_is_an_error_not_a_dropped_camera():
    with pytest.raises(SystemExit, match="outnumber"):
        vla.rename_map([TOP, WRIST, "observation.images.front"], PRETRAINED[:2], None)


def arguments(name: str, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    vla.add_arguments(parser, name)
    args = parser.parse_args(["--dataset", "/data/two_tasks", *argv])
    args.device = "cuda"
    return args


def test_smolvla_starts_from_the_pretrained_policy_with_the_camera_map(tmp_path):
    args = arguments("smolvla")
    command = vla.train_command(args, tmp_path / "out", {TOP: PRETRAINED[0]})
    assert command[0].endswith("lerobot-train")
    assert "--policy.path=lerobot/smolvla_base" in command and "--policy.device=cuda" in command
    assert "--steps=20000" in command and "--batch_size=64" in command
    (rename,) = [item for item in command if item.startswith("--rename_map=")]
    assert json.loads(rename.removeprefix("--rename_map=")) == {TOP: PRETRAINED[0]}
    assert f"--dataset.root={Path('/data/two_tasks').resolve()}" in command


def test_pi0_starts_as_lerobot_documents_it(tmp_path):
    command = vla.train_command(arguments("pi0"), tmp_path / "out", {})
    assert "--policy.type=pi0" in command and "--policy.pretrained_path=lerobot/pi0_base" in command
    assert not [item for item in command if item.startswith(("--policy.path=", "--rename_map="))]
    assert {"--policy.dtype=bfloat16", "--policy.gradient_checkpointing=true", "--steps=3000", "--batch_size=32"} <= set(command)


def test_the_checkpoints_keep_the_dataset_s_features(tmp_path):
    from so101.evaluate.policy import DATASET_FEATURES_FILE, training_features

    dataset = tmp_path / "dataset"
    (dataset / "meta").mkdir(parents=True)
    features = {TOP: {"dtype": "video", "shape": [72, 96, 3]}}
    (dataset / "meta" / "info.json").write_text(json.dumps({"features": features}))
    checkpoints = [tmp_path / "out" / "checkpoints" / step / "pretrained_model" for step in ("000003", "last")]
    for checkpoint in checkpoints:
        checkpoint.mkdir(parents=True)
    vla.keep_dataset_features(dataset, tmp_path / "out")
    for checkpoint in checkpoints:
        assert (checkpoint / DATASET_FEATURES_FILE).is_file()
        assert training_features(str(checkpoint)) == features  # no train_config.json needed


def test_several_gpus_launch_through_accelerate(tmp_path):
    args = arguments("smolvla", "--pretrained", "/weights/mine", "--num-processes", "2")
    command = vla.train_command(args, tmp_path / "out", {})
    assert command[0].endswith("accelerate") and "--num_processes=2" in command
    assert "--policy.path=/weights/mine" in command


def test_frames_at_the_training_dataset_s_size_under_the_stack_s_names():
    visual = {key: (3, 256, 256) for key in PRETRAINED}
    renamed = {PRETRAINED[0]: TOP, PRETRAINED[1]: WRIST}
    trained_on = {TOP: {"shape": [72, 96, 3]}, WRIST: {"shape": [48, 64, 3]}}
    cameras = camera_inputs(visual, renamed, trained_on, optional_images=True)
    assert cameras == [CameraInput("top", 72, 96), CameraInput("wrist", 48, 64)]  # camera3: padded by the model


def test_act_takes_its_own_inputs_whatever_its_dataset_became():
    # lerobot-train filled the config from the dataset: names and sizes stand even when the
    # dataset at that path was recorded again with other cameras or sizes.
    visual = {TOP: (3, 48, 64), "observation.images.laptop": (3, 72, 96)}
    regenerated = {WRIST: {"shape": [96, 128, 3]}}
    expected = [CameraInput("top", 48, 64), CameraInput("laptop", 72, 96)]
    assert camera_inputs(visual, {}, regenerated, optional_images=False) == expected
    assert camera_inputs(visual, {}, None, optional_images=False) == expected
    with pytest.raises(PolicyError, match="not observation.images"):
        camera_inputs({"observation.image": (3, 48, 64)}, {}, None, optional_images=False)


def test_a_vla_fed_by_no_camera_is_refused():
    with pytest.raises(PolicyError, match="no camera of the stack"):
        camera_inputs({key: (3, 256, 256) for key in PRETRAINED}, {}, None, optional_images=True)


@pytest.fixture
def without_transformers(monkeypatch):
    """This environment as setup_python.sh makes the main one: no transformers (the VLAs' own is .venv-vla)."""
    import importlib.util

    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "transformers" else find_spec(name, *a))


def test_without_the_vla_packages_the_recipe_says_where_they_are(without_transformers):
    with pytest.raises(
        SystemExit, match=r"so101-learn smolvla: a smolvla policy needs transformers .*\.venv-vla/bin/so101-learn smolvla"
    ):
        vla.run(arguments("smolvla"))


def test_without_the_vla_packages_the_runner_refuses_a_vla_checkpoint_with_the_reason(without_transformers, tmp_path):
    from so101.evaluate.policy import StackPolicy

    (tmp_path / "config.json").write_text(json.dumps({"type": "smolvla"}))
    with pytest.raises(PolicyError, match=r"needs transformers .*\.venv-vla/bin/so101-run-policy"):
        StackPolicy(str(tmp_path), device="cpu")
